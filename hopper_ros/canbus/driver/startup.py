"""The drive's configuration: the PDO layout, the start-up SDO sequence and the shutdown sequence.

Start-up (non-blocking, one SDO at a time): NMT pre-operational, controlword "disable voltage",
device type check, the drive's last error code, heartbeat producer (0x1017) and consumer of our
heartbeat (0x1016: the drive faults by itself if this process dies), current limits (0x6410),
position regulator gains (0x60FB), operating mode, the PDO layout below, NMT start.

PDOs (RPDOs event-driven so a command acts when it arrives; TPDOs on every SYNC):
  RPDO1 controlword, modes of operation, current mode setting value [mA]    (current and disabled)
  RPDO2 controlword, modes of operation, position mode setting value [qc]   (position)
  TPDO1 statusword, position actual value [qc], current actual value [mA]
  TPDO2 velocity actual value [rpm], modes of operation display, error code

A sequence is a list of steps the driver carries out in order (`MotorDriver._advance`):
("nmt", command), ("download", index, sub, struct format, value), ("upload", index, sub, check),
("pdo_disable", deadline), ("running",), ("stopped",).
"""

from __future__ import annotations

from typing import Callable

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_objects import Command, NmtCommand, OperationMode
from hopper_ros.canbus.cia301.master import PdoEntry, PdoMapping, SdoTransfer

from .settings import DriveConfig, DriverSettings

_CW = PdoEntry(eo.CONTROLWORD, 0, 16, False, "controlword")
_MODE = PdoEntry(eo.MODES_OF_OPERATION, 0, 8, True, "modes_of_operation")
RPDO_MAPPINGS: dict[int, PdoMapping] = {
    1: PdoMapping.of([_CW, _MODE, PdoEntry(eo.CURRENT_MODE_SETTING_VALUE, 0, 16, True, "current_setting_mA")]),
    2: PdoMapping.of([_CW, _MODE, PdoEntry(eo.POSITION_MODE_SETTING_VALUE, 0, 32, True, "position_setting_qc")]),
}
TPDO_MAPPINGS: dict[int, PdoMapping] = {
    1: PdoMapping.of([PdoEntry(eo.STATUSWORD, 0, 16, False, "statusword"),
                      PdoEntry(eo.POSITION_ACTUAL_VALUE, 0, 32, True, "position_qc"),
                      PdoEntry(eo.CURRENT_ACTUAL_VALUE, 0, 16, True, "current_mA")]),
    2: PdoMapping.of([PdoEntry(eo.VELOCITY_ACTUAL_VALUE, 0, 32, True, "velocity_rpm"),
                      PdoEntry(eo.MODES_OF_OPERATION_DISPLAY, 0, 8, True, "modes_of_operation_display"),
                      PdoEntry(eo.ERROR_CODE, 0, 16, False, "error_code")]),
}
RPDO_TRANSMISSION = eo.TRANSMISSION_EVENT   # 255: applied on reception
TPDO_TRANSMISSION = 1                       # sent after every SYNC

Check = Callable[[SdoTransfer], None]


def _ms(seconds: float) -> int:
    return max(1, round(seconds * 1000.0))


def pdo_steps(node_id: int) -> list[tuple]:
    """Every PDO invalidated, then the used ones mapped, given their transmission type and valid again."""
    steps: list[tuple] = []
    for kind, comm, mapping_base, mappings, transmission in (
            ("rpdo", eo.RPDO_COMMUNICATION, eo.RPDO_MAPPING, RPDO_MAPPINGS, RPDO_TRANSMISSION),
            ("tpdo", eo.TPDO_COMMUNICATION, eo.TPDO_MAPPING, TPDO_MAPPINGS, TPDO_TRANSMISSION)):
        cob_of = eo.rpdo_cob_id if kind == "rpdo" else eo.tpdo_cob_id
        for number in range(1, eo.PDO_COUNT + 1):
            cob = cob_of(number, node_id)
            steps.append(("download", comm + number - 1, eo.PDO_COB_ID_SUB, "<I", cob | eo.COB_ID_INVALID_BIT))
            mapping = mappings.get(number)
            if mapping is None:
                continue                       # unused: stays disabled
            steps.append(("download", comm + number - 1, eo.PDO_TRANSMISSION_TYPE_SUB, "<B", transmission))
            steps.append(("download", mapping_base + number - 1, 0, "<B", 0))
            for sub, entry in enumerate(mapping.entries, start=1):
                steps.append(("download", mapping_base + number - 1, sub, "<I", entry.mapping))
            steps.append(("download", mapping_base + number - 1, 0, "<B", len(mapping.entries)))
            steps.append(("download", comm + number - 1, eo.PDO_COB_ID_SUB, "<I", cob))
    return steps


def startup_steps(drive: DriveConfig, settings: DriverSettings, check_device_type: Check,
                  record_error_code: Check) -> list[tuple]:
    """The start-up sequence (module docstring), ending in ("running",)."""
    consumer = (settings.master_node_id << 16 | _ms(settings.drive_consumer_time)) if settings.drive_consumer_time else 0
    steps: list[tuple] = [
        ("nmt", NmtCommand.ENTER_PRE_OPERATIONAL),
        ("download", eo.CONTROLWORD, 0, "<H", int(Command.DISABLE_VOLTAGE)),
        ("upload", eo.DEVICE_TYPE, 0, check_device_type),
        ("upload", eo.ERROR_CODE, 0, record_error_code),
        ("download", eo.PRODUCER_HEARTBEAT_TIME, 0, "<H", _ms(drive.heartbeat_period)),
        ("download", eo.CONSUMER_HEARTBEAT_TIME, 1, "<I", consumer),
        ("download", eo.MOTOR_DATA, eo.MOTOR_CONTINUOUS_CURRENT_LIMIT_SUB, "<H", round(drive.continuous_current * 1000)),
        ("download", eo.MOTOR_DATA, eo.MOTOR_OUTPUT_CURRENT_LIMIT_SUB, "<H", round(drive.current_limit * 1000)),
    ]
    for sub, gain in zip((eo.GAIN_P_SUB, eo.GAIN_I_SUB, eo.GAIN_D_SUB), drive.position_gains):
        steps.append(("download", eo.POSITION_CONTROL_PARAMETERS, sub, "<h", gain))
    steps.append(("download", eo.MODES_OF_OPERATION, 0, "<b", int(OperationMode.CURRENT)))
    return steps + pdo_steps(drive.node_id) + [("nmt", NmtCommand.START), ("running",)]


def shutdown_steps(pdo_disable_until: float | None, settings: DriverSettings, check_disabled: Check) -> list[tuple]:
    """Power stage off (by PDO until `pdo_disable_until` when running, then by SDO), statusword read
    back, the drive's consumer of our heartbeat off, NMT pre-operational; ending in ("stopped",)."""
    steps: list[tuple] = [] if pdo_disable_until is None else [("pdo_disable", pdo_disable_until)]
    steps += [
        ("download", eo.CONTROLWORD, 0, "<H", int(Command.DISABLE_VOLTAGE)),
        ("upload", eo.STATUSWORD, 0, check_disabled),
    ]
    if settings.drive_consumer_time:
        steps.append(("download", eo.CONSUMER_HEARTBEAT_TIME, 1, "<I", 0))
    return steps + [("nmt", NmtCommand.ENTER_PRE_OPERATIONAL), ("stopped",)]


def check_device_type(node_id: int, transfer: SdoTransfer) -> None:
    """ValueError unless the drive's device type (0x1000) is a CiA 402 drive's."""
    device_type = transfer.value("<I")
    if device_type & 0xFFFF != eo.DEVICE_TYPE_VALUE & 0xFFFF:
        raise ValueError(f"node {node_id} is not a CiA 402 drive (device type 0x{device_type:08X})")
