"""The hip motor driver: CANopen master of the maxon EPOS2, as plain Python (no ROS).

- `settings`  DriverSettings and MotorDriverConfig (config/motor_driver.yaml), DriveConfig (hardware.yaml),
              modes, levels
- `bus`       the transport (python-can's bus config): the driver's end and the simulated drive's
- `cia402`    the CiA 402 device control as tables, the fault reset's edges
- `startup`   the PDO layout, the start-up SDO sequence and the shutdown sequence
- `units`     SI <-> drive units (mA, qc, rpm)
- `driver`    MotorDriver: commands, the SYNC cycle, frames out, safety (command watchdog, faults)
- `received`  its handling of received frames: TPDOs, SDO answers, EMCY, heartbeats, state changes
- `sequence`  its start-up and shutdown sequences run against the drive (retries, failures)
- `status`    DriveStatus, Phase, how a bus failure reads
- `cycle`     CycleLoop: the 1 kHz loop in a thread of its own (what the node runs)
The node hopper_ros/nodes/motor_driver.py adapts it to ROS. Description: docs/motor_driver.md.
"""

from .bus import Transport, open_bus, open_drive_side, select_transport, sim_transport
from .driver import DriveStatus, MotorDriver, Phase
from .settings import (COUNTER_NAMES, ERROR, INFO, MODE_CURRENT, MODE_DISABLED, MODE_NAMES, MODE_POSITION, MODE_RAMP,
                       NODE_KEYS, WARN, DriveConfig, DriverSettings, MotorDriverConfig,
                       load_motor_driver)

__all__ = ["Transport", "open_bus", "open_drive_side", "select_transport", "sim_transport", "DriveStatus",
           "MotorDriver", "Phase", "COUNTER_NAMES", "ERROR", "INFO", "MODE_CURRENT", "MODE_DISABLED", "MODE_NAMES",
           "MODE_POSITION", "MODE_RAMP", "NODE_KEYS", "WARN", "DriveConfig", "DriverSettings", "MotorDriverConfig",
           "load_motor_driver"]
