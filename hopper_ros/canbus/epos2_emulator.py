"""An emulated maxon EPOS2 on a python-can bus: the simulated robot's hip drive. No ROS.

CiA 301: NMT (start, stop, pre-operational, reset node / communication, boot-up), SDO server
(expedited and segmented upload and download; CiA 301 abort codes for anything it cannot do),
4 RPDOs and 4 TPDOs with remapping by SDO, SYNC consumer, heartbeat producer (0x1017) and
consumer (0x1016), EMCY producer with error register (0x1001), error history (0x1003).
CiA 402 as the EPOS2 implements it: the device state machine driven by the controlword, the
EPOS2 statusword values, Current Mode (-3, setpoint 0x2030 [mA]) and Position Mode (-1,
setpoint 0x2062 [qc], PID of `epos2_regulator`). Other EPOS2 modes are accepted in 0x6060 but
not regulated (demand 0).

Single-threaded: the owner calls `poll(now)` (handle received frames) and `control(now, ...)`
(the 1 kHz drive cycle) from one thread; `now` is the owner's clock (simulation time) [s].
Malformed input never raises: it is counted in `malformed_frames` and answered like a CiA 301
device (SDO abort, EMCY 0x8210 for an RPDO of the wrong length). Details: docs/canopen.md.

The SDO server and the PDO engine are the generic CiA 301 pieces of hopper_ros/canbus/cia301/
(`sdo_server`, `pdo`); this module holds the EPOS2: its dictionary's values and rules, NMT, heartbeat, EMCY
and the error history, CiA 402 device control and the modes' regulation.
"""

from __future__ import annotations

import logging
import struct
from collections import deque

import can

from hopper_ros.canbus import epos2_objects as od
from hopper_ros.canbus.cia301.counters import Counters
from hopper_ros.canbus.cia301.pdo import PdoEngine
from hopper_ros.canbus.cia301.sdo_server import MAX_SEGMENTED_SIZE, SdoRefused, SdoServer
from hopper_ros.canbus.cia301.values import decode, encode, saturate, wrap_i32
from hopper_ros.canbus.epos2_objects import (
    Command,
    NmtCommand,
    NmtState,
    OperationMode,
    SdoAbort,
    State,
)
from hopper_ros.canbus.epos2_regulator import POSITION_LOOP_PERIOD, PositionGains, PositionRegulator
from hopper_ros.hardware.config import HardwareConfig

log = logging.getLogger(__name__)

_MILLI = 1.0e-3
_MS = 1.0e-3                       # [s/ms]
#: time constant of the "averaged" feedback objects 0x2027 / 0x2028 [s] (emulation choice)
AVERAGING_TIME_CONSTANT = 0.01
_ENABLED_STATES = (State.OPERATION_ENABLED,)
_SAMPLE_TOLERANCE = 0.999          # a control() call this close to one loop period counts as one

# The drive's side of CiA 402 device control: a command is (controlword mask, value); per state, the
# commands tried in this order and the state each leads to.
_SHUTDOWN, _SWITCH_ON, _ENABLE = (0x87, Command.SHUTDOWN), (0x8F, Command.SWITCH_ON), (0x8F, Command.ENABLE_OPERATION)
_DISABLE_VOLTAGE, _QUICK_STOP = (0x82, Command.DISABLE_VOLTAGE), (0x86, Command.QUICK_STOP)
_TRANSITIONS = {
    State.SWITCH_ON_DISABLED: ((_SHUTDOWN, State.READY_TO_SWITCH_ON),),
    State.READY_TO_SWITCH_ON: ((_SWITCH_ON, State.SWITCHED_ON), (_ENABLE, State.OPERATION_ENABLED),
                               (_DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED), (_QUICK_STOP, State.SWITCH_ON_DISABLED)),
    State.SWITCHED_ON: ((_ENABLE, State.OPERATION_ENABLED), (_SHUTDOWN, State.READY_TO_SWITCH_ON),
                        (_DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED), (_QUICK_STOP, State.SWITCH_ON_DISABLED)),
    State.OPERATION_ENABLED: ((_SWITCH_ON, State.SWITCHED_ON),          # switch on = disable operation
                              (_SHUTDOWN, State.READY_TO_SWITCH_ON), (_DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED),
                              (_QUICK_STOP, State.QUICK_STOP_ACTIVE)),
    State.QUICK_STOP_ACTIVE: ((_DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED), (_ENABLE, State.OPERATION_ENABLED)),
}


class Epos2Emulator:
    """The emulated EPOS2. See the module docstring for the calling contract."""

    def __init__(self, bus: can.BusABC, hardware: HardwareConfig, *, node_id: int | None = None):
        self.bus = bus
        self.node_id = int(hardware.drive.node_id if node_id is None else node_id)
        self._hardware = hardware
        self._table = od.object_dictionary(self.node_id)
        self._indices = {index for index, _ in self._table}
        self.counters = Counters()
        self._held: deque[tuple[can.Message, bool]] = deque()   # frames queued while the drive stood still
                                                    # (discard_syncs), handled first: (frame, its SYNC unanswered)
        self.regulator = PositionRegulator.from_hardware(hardware)
        self._values: dict[tuple[int, int], int | str] = {}
        self.sdo = SdoServer(self.node_id, self, self._send, self.counters, MAX_SEGMENTED_SIZE)
        self.pdos = PdoEngine(self._table, self._values, self._send, self.counters,
                              lambda: self.nmt_state == NmtState.OPERATIONAL, self._store, self._raise_error)
        self._reset_all()
        self.nmt_state = NmtState.PRE_OPERATIONAL
        self._send_bootup()

    # ---------------------------------------------------------------- configuration & reset

    def _config_defaults(self) -> dict[tuple[int, int], int]:
        """Values taken from config/hardware.yaml instead of the factory defaults."""
        drive = self._hardware.drive
        gains = drive.position_gains
        return {
            (od.MOTOR_DATA, od.MOTOR_CONTINUOUS_CURRENT_LIMIT_SUB): round(drive.continuous_current / _MILLI),
            (od.MOTOR_DATA, od.MOTOR_OUTPUT_CURRENT_LIMIT_SUB): round(drive.current_limit / _MILLI),
            (od.POSITION_CONTROL_PARAMETERS, od.GAIN_P_SUB): gains.p,
            (od.POSITION_CONTROL_PARAMETERS, od.GAIN_I_SUB): gains.i,
            (od.POSITION_CONTROL_PARAMETERS, od.GAIN_D_SUB): gains.d,
            (od.PRODUCER_HEARTBEAT_TIME, 0): round(drive.heartbeat_period / _MS),
            (od.SENSOR_CONFIGURATION, od.SENSOR_PULSE_NUMBER_SUB): self._hardware.encoders.motor.lines,
        }

    def _reset_communication(self) -> None:
        for key, entry in self._table.items():
            if key[0] < 0x2000:
                self._values[key] = entry.default
        for key, value in self._config_defaults().items():
            if key[0] < 0x2000:
                self._values[key] = value
        self.sdo.reset()
        self.pdos.reset()
        self._next_heartbeat: float | None = None
        self._consumer_last: float | None = None
        self._error_history: list[int] = []

    def _reset_all(self) -> None:
        for key, entry in self._table.items():
            self._values[key] = entry.default
        for key, value in self._config_defaults().items():
            self._values[key] = value
        self._reset_communication()
        self.state = State.SWITCH_ON_DISABLED
        self._controlword = 0
        self._errors: list[int] = []
        self.demand = 0.0
        self._average_current = 0.0
        self._average_velocity = 0.0
        self._last_control: float | None = None
        self._next_regulation: float | None = None
        self.regulator.reset()
        self._update_statusword()

    # ---------------------------------------------------------------- public properties

    @property
    def statusword(self) -> int:
        return int(self._values[(od.STATUSWORD, 0)])

    @property
    def controlword(self) -> int:
        return self._controlword

    @property
    def operation_mode(self) -> int:
        """Modes of operation display (0x6061); an OperationMode value."""
        return int(self._values[(od.MODES_OF_OPERATION_DISPLAY, 0)])

    @property
    def error_code(self) -> int:
        return int(self._values[(od.ERROR_CODE, 0)])

    @property
    def error_register(self) -> int:
        return int(self._values[(od.ERROR_REGISTER, 0)])

    @property
    def malformed_frames(self) -> int:
        return self.counters.malformed_frames

    @property
    def output_current_limit(self) -> float:
        """[A] object 0x6410 sub 2."""
        return int(self._values[(od.MOTOR_DATA, od.MOTOR_OUTPUT_CURRENT_LIMIT_SUB)]) * _MILLI

    def value(self, index: int, subindex: int = 0) -> int | str:
        """Current value of a dictionary entry (for the simulation and tests)."""
        return self._values[(index, subindex)]

    # ---------------------------------------------------------------- bus input

    def poll(self, now: float, one_sync: bool = False) -> None:
        """Handle every frame pending on the bus; with `one_sync`, up to and including the first SYNC
        (the simulated robot catching up on a short stall runs one SYNC period a step, the drive then
        applying each RPDO at its own SYNC as it would have on time)."""
        while True:
            msg, unseen = self._held.popleft() if self._held else (self._receive(), False)
            if msg is None:
                return
            try:
                if self._handle(msg, now, unseen) and one_sync:
                    return
            except Exception:                    # never let one frame kill the drive
                self.counters.malformed_frames += 1
                log.exception("EPOS2 emulator: frame %s not handled", msg)

    def discard_syncs(self, answered: int = 0) -> int:
        """The drive stood still (the simulated robot's process stopped and its world with it): every
        frame queued for it now came meanwhile. They are handled in order at the next polls, but none of
        their SYNCs is answered (`counters.syncs_missed`), as a drive that stood still never saw them; the
        motor driver counts the SYNCs left unanswered as the time the robot stood still. The SYNCs are
        those queued, not a count from the time stood still: the master's SYNCs of that time may be
        fewer (its own process starved, its cycle skipping), and the answers then withheld from SYNCs
        that came after the drive woke held the stance ramp's current back (test_drive_stillness; suspected
        in a loaded 500 Hz run's torque 5.7 ms after a touchdown, docs/sim.md). The owner first has the
        transport take in what has reached it (the hub's `read_pending`); a frame its sender still held
        comes after and is answered, the stand-still counted that much short. The first `answered` SYNCs queued
        came before the world stood still (the period it stopped in, whose step never ran): they are answered
        (all discarded, the driver's count of a stand-still ran 1-5 ms over the time the world stood still,
        2 ms on average at 500 Hz: bench_demo_load with --bag, docs/sim.md). Returns how many will not be."""
        for_the_period, unanswered = answered, 0
        while (msg := self._receive()) is not None:
            is_sync = msg.arbitration_id == self._sync_cob()
            self._held.append((msg, not for_the_period))
            unanswered += is_sync and not for_the_period
            for_the_period -= bool(is_sync and for_the_period)
        return unanswered

    def _sync_cob(self) -> int:
        """The SYNC's COB-ID as object 0x1005 sets it."""
        return int(self._values[(od.COB_ID_SYNC, 0)]) & od.COB_ID_MASK_11BIT

    def _receive(self) -> can.Message | None:
        """The next frame on the bus, None when none is pending."""
        try:
            return self.bus.recv(timeout=0)
        except can.CanError as exc:              # a broken transport is the owner's problem;
            log.warning("EPOS2 emulator: receive failed: %s", exc)   # the drive survives
            return None

    def _handle(self, msg: can.Message, now: float, unseen: bool = False) -> bool:
        """Handle one frame; True if it was a SYNC answered. `unseen`: it came while the drive stood still."""
        if msg.is_error_frame or msg.is_extended_id:
            return False                         # not CANopen traffic
        cob = msg.arbitration_id
        data = bytes(msg.data)
        if cob == od.NMT_COB_ID:
            self._on_nmt(data, now)
            return
        if self.nmt_state == NmtState.STOPPED:
            self._on_consumer_heartbeat(cob, data, now)
            return
        if msg.is_remote_frame:
            self.pdos.on_remote(cob, now)
            return
        if cob == od.sdo_rx_cob_id(self.node_id):
            self.sdo.on_frame(data)
        elif cob == self._sync_cob():
            if unseen:
                self.counters.syncs_missed += 1
                return False
            self.pdos.on_sync(data, now)
            return True
        elif (rpdo := self.pdos.rpdo_number(cob)) is not None:
            self.pdos.on_rpdo(rpdo, data, now)
        else:
            self._on_consumer_heartbeat(cob, data, now)

    def _send(self, cob: int, data: bytes) -> None:
        try:
            self.bus.send(can.Message(arbitration_id=cob, data=data, is_extended_id=False))
        except can.CanError as exc:
            log.warning("EPOS2 emulator: send of 0x%03X failed: %s", cob, exc)

    # ---------------------------------------------------------------- NMT and heartbeat

    def _send_bootup(self) -> None:
        self._send(od.heartbeat_cob_id(self.node_id), bytes([NmtState.BOOTUP]))

    def _on_nmt(self, data: bytes, now: float) -> None:
        if len(data) != 2:
            self.counters.malformed_frames += 1
            return
        command, target = data
        if target not in (od.NMT_BROADCAST_NODE, self.node_id):
            return
        if command == NmtCommand.START:
            self.nmt_state = NmtState.OPERATIONAL
        elif command == NmtCommand.STOP:
            self.nmt_state = NmtState.STOPPED
        elif command == NmtCommand.ENTER_PRE_OPERATIONAL:
            self.nmt_state = NmtState.PRE_OPERATIONAL
        elif command == NmtCommand.RESET_NODE:
            self._reset_all()
            self.nmt_state = NmtState.PRE_OPERATIONAL
            self._send_bootup()
        elif command == NmtCommand.RESET_COMMUNICATION:
            self._reset_communication()
            self.nmt_state = NmtState.PRE_OPERATIONAL
            self._send_bootup()
        else:
            self.counters.malformed_frames += 1

    def _consumer(self) -> tuple[int, float] | None:
        raw = int(self._values[(od.CONSUMER_HEARTBEAT_TIME, 1)])
        node, time_ms = (raw >> 16) & 0x7F, raw & 0xFFFF
        if node == 0 or time_ms == 0:
            return None
        return node, time_ms * _MS

    def _on_consumer_heartbeat(self, cob: int, data: bytes, now: float) -> None:
        consumer = self._consumer()
        if consumer and cob == od.HEARTBEAT_BASE + consumer[0] and len(data) >= 1:
            self._consumer_last = now

    def _heartbeat(self, now: float) -> None:
        period = int(self._values[(od.PRODUCER_HEARTBEAT_TIME, 0)]) * _MS
        if period <= 0:
            self._next_heartbeat = None
        elif self._next_heartbeat is None or now >= self._next_heartbeat:
            self._send(od.heartbeat_cob_id(self.node_id), bytes([self.nmt_state]))
            base = now if self._next_heartbeat is None else self._next_heartbeat
            self._next_heartbeat = max(base + period, now)
        consumer = self._consumer()
        if consumer is None:
            self._consumer_last = None
        elif self._consumer_last is not None and now - self._consumer_last > consumer[1]:
            self._consumer_last = None           # re-armed by the next heartbeat
            self._raise_error(od.ERROR_LIFE_GUARD, now)

    # ---------------------------------------------------------------- errors and EMCY

    def inject_fault(self, code: int, now: float) -> None:
        """An error inside the drive (e.g. 0x2310 over current): EMCY and FAULT."""
        self._raise_error(int(code) & 0xFFFF, now)

    def _raise_error(self, code: int, now: float) -> None:
        self._errors.append(code)
        self._error_history.insert(0, code)
        del self._error_history[od.ERROR_HISTORY_LENGTH:]
        register = od.ErrorRegisterBit.GENERIC
        for c in self._errors:
            register |= od.error_register_bits(c)
        self._values[(od.ERROR_REGISTER, 0)] = int(register)
        self._values[(od.ERROR_CODE, 0)] = code
        self._sync_error_history()
        self._send_emcy(code, int(register))
        if self.state != State.FAULT:
            self.state = State.FAULT
            self.demand = 0.0
            self.regulator.reset()
        self._update_statusword()
        log.info("EPOS2 emulator: error 0x%04X %s", code, od.error_text(code))

    def _sync_error_history(self) -> None:
        self._values[(od.ERROR_HISTORY, 0)] = len(self._error_history)
        for sub in range(1, od.ERROR_HISTORY_LENGTH + 1):
            h = self._error_history
            self._values[(od.ERROR_HISTORY, sub)] = h[sub - 1] if sub <= len(h) else 0

    def _send_emcy(self, code: int, register: int) -> None:
        cob = int(self._values[(od.COB_ID_EMCY, 0)])
        if cob & od.COB_ID_INVALID_BIT:
            return
        self._send(cob & od.COB_ID_MASK_11BIT, struct.pack("<HB5s", code, register, bytes(5)))
        self.counters.emcy_sent += 1

    def _clear_errors(self) -> None:
        self._errors.clear()
        self._values[(od.ERROR_REGISTER, 0)] = 0
        self._values[(od.ERROR_CODE, 0)] = od.ERROR_NONE
        self._send_emcy(od.ERROR_NONE, 0)

    # ---------------------------------------------------------------- CiA 402 device control

    def _on_controlword(self, cw: int) -> None:
        previous, self._controlword = self._controlword, cw & 0xFFFF
        s = self.state
        if s == State.FAULT:
            if cw & (1 << od.ControlwordBit.FAULT_RESET) and not previous & (1 << od.ControlwordBit.FAULT_RESET):
                self._clear_errors()
                self.state = State.SWITCH_ON_DISABLED
            self._update_statusword()
            return
        if cw & (1 << od.ControlwordBit.FAULT_RESET):
            self._update_statusword()
            return                               # bit 7 set: no other command (CiA 402)
        s = next((target for (mask, value), target in _TRANSITIONS.get(s, ()) if cw & mask == value), s)
        if s != self.state:
            if s == State.OPERATION_ENABLED:
                self.regulator.reset(int(self._values[(od.POSITION_ACTUAL_VALUE, 0)]))
            else:
                self.demand = 0.0
            self.state = s
        self._update_statusword()

    def _update_statusword(self) -> None:
        sw = od.STATUSWORD_OF_STATE[self.state]
        self._values[(od.STATUSWORD, 0)] = sw

    def _on_mode(self, mode: int) -> None:
        if mode != self._values[(od.MODES_OF_OPERATION_DISPLAY, 0)]:
            self.regulator.reset(int(self._values[(od.POSITION_ACTUAL_VALUE, 0)]))
        self._values[(od.MODES_OF_OPERATION_DISPLAY, 0)] = mode

    # ---------------------------------------------------------------- the 1 kHz drive cycle

    def control(self, now: float, position_counts: int, velocity_rpm: float, current_a: float) -> float:
        """One drive cycle: feedback objects, heartbeat, regulator; the current demand [A]."""
        dt = 0.0 if self._last_control is None else max(0.0, now - self._last_control)
        self._last_control = now
        alpha = 1.0 if dt <= 0 else min(1.0, dt / AVERAGING_TIME_CONSTANT)
        self._average_current += alpha * (current_a - self._average_current)
        self._average_velocity += alpha * (velocity_rpm - self._average_velocity)
        v = self._values
        v[(od.POSITION_ACTUAL_VALUE, 0)] = wrap_i32(int(position_counts))
        v[(od.ENCODER_COUNTER, 0)] = int(position_counts) & 0xFFFF
        v[(od.VELOCITY_ACTUAL_VALUE, 0)] = saturate(round(velocity_rpm), 32)
        v[(od.CURRENT_ACTUAL_VALUE, 0)] = saturate(round(current_a / _MILLI), 16)
        v[(od.CURRENT_ACTUAL_VALUE_AVERAGED, 0)] = saturate(round(self._average_current / _MILLI), 16)
        v[(od.VELOCITY_ACTUAL_VALUE_AVERAGED, 0)] = saturate(round(self._average_velocity), 32)
        self._heartbeat(now)
        self.demand = self._regulate(now, int(v[(od.POSITION_ACTUAL_VALUE, 0)]))
        v[(od.CURRENT_DEMAND_VALUE, 0)] = round(self.demand / _MILLI)
        if self.nmt_state == NmtState.OPERATIONAL:
            self.pdos.event_tpdos(now)
        return self.demand

    def _regulate(self, now: float, position: int) -> float:
        if self.state not in _ENABLED_STATES:
            self._next_regulation = None
            return 0.0
        limit = self.output_current_limit
        mode = self.operation_mode
        v = self._values
        if mode == OperationMode.CURRENT:
            return max(-limit, min(limit, int(v[(od.CURRENT_MODE_SETTING_VALUE, 0)]) * _MILLI))
        if mode != OperationMode.POSITION:
            return 0.0
        if self._next_regulation is not None and now < self._next_regulation:
            return self.demand                   # hold between position-loop samples
        self._next_regulation = now + POSITION_LOOP_PERIOD * _SAMPLE_TOLERANCE
        self.regulator.gains = PositionGains(
            int(v[(od.POSITION_CONTROL_PARAMETERS, od.GAIN_P_SUB)]),
            int(v[(od.POSITION_CONTROL_PARAMETERS, od.GAIN_I_SUB)]),
            int(v[(od.POSITION_CONTROL_PARAMETERS, od.GAIN_D_SUB)]),
        )
        self.regulator.current_limit = limit
        setpoint = int(v[(od.POSITION_MODE_SETTING_VALUE, 0)])
        v[(od.POSITION_DEMAND_VALUE, 0)] = setpoint
        following = setpoint - position
        v[(od.FOLLOWING_ERROR_ACTUAL_VALUE, 0)] = saturate(following, 16)
        if abs(following) > int(v[(od.MAX_FOLLOWING_ERROR, 0)]):
            self._raise_error(od.ERROR_FOLLOWING, now)
            return 0.0
        return self.regulator.update(setpoint, position)

    # ---------------------------------------------------------------- dictionary access

    def _entry(self, index: int, sub: int) -> od.ODEntry:
        entry = self._table.get((index, sub))
        if entry is None:
            raise SdoRefused(SdoAbort.OBJECT_DOES_NOT_EXIST if index not in self._indices
                           else SdoAbort.SUBINDEX_DOES_NOT_EXIST)
        return entry

    def size_of(self, index: int, sub: int) -> int | None:
        return od.data_type_size(self._entry(index, sub).data_type)

    def check_writable(self, index: int, sub: int) -> od.ODEntry:
        entry = self._entry(index, sub)
        if not entry.access.writable:
            raise SdoRefused(SdoAbort.READ_ONLY)
        return entry

    def read(self, index: int, sub: int) -> bytes:
        """SDO upload of one entry as bytes; raises SdoRefused with the abort code."""
        entry = self._entry(index, sub)
        if not entry.access.readable:
            raise SdoRefused(SdoAbort.WRITE_ONLY)
        return encode(entry.data_type, self._values[(index, sub)])

    def write(self, index: int, sub: int, payload: bytes) -> None:
        """SDO download of one entry; raises SdoRefused with the abort code."""
        entry = self.check_writable(index, sub)
        size = od.data_type_size(entry.data_type)
        if size is not None and len(payload) != size:
            raise SdoRefused(SdoAbort.LENGTH_MISMATCH)
        value = decode(entry.data_type, payload)
        self._validate(entry, value)
        self._store(entry, value)

    def _validate(self, entry: od.ODEntry, value: int | str) -> None:
        index, sub = entry.index, entry.subindex
        if index == od.ERROR_HISTORY and sub == 0 and value != 0:
            raise SdoRefused(SdoAbort.INVALID_VALUE)
        if index == od.STORE_PARAMETERS and value != od.STORE_SIGNATURE:
            raise SdoRefused(SdoAbort.CANNOT_TRANSFER)
        if index == od.RESTORE_DEFAULT_PARAMETERS and value != od.RESTORE_SIGNATURE:
            raise SdoRefused(SdoAbort.CANNOT_TRANSFER)
        if index == od.MODES_OF_OPERATION and value not in set(OperationMode):
            raise SdoRefused(SdoAbort.INVALID_VALUE)
        if index == od.NODE_ID and not od.NODE_ID_MIN <= int(value) <= od.NODE_ID_MAX:
            raise SdoRefused(SdoAbort.INVALID_VALUE)
        if index == od.MOTOR_DATA and sub in (od.MOTOR_CONTINUOUS_CURRENT_LIMIT_SUB,
                                              od.MOTOR_OUTPUT_CURRENT_LIMIT_SUB) and value == 0:
            raise SdoRefused(SdoAbort.VALUE_TOO_LOW)
        if index == od.CONSUMER_HEARTBEAT_TIME and (int(value) >> 16) & 0xFF == self.node_id and value & 0xFFFF:
            raise SdoRefused(SdoAbort.PARAMETER_INCOMPATIBILITY)
        self.pdos.validate(entry, value)              # the CiA 301 rules of the PDO objects

    def _store(self, entry: od.ODEntry, value: int | str) -> None:
        key = (entry.index, entry.subindex)
        if entry.index == od.ERROR_HISTORY:
            self._error_history.clear()
            self._sync_error_history()
            return
        if entry.index == od.RESTORE_DEFAULT_PARAMETERS or entry.index == od.STORE_PARAMETERS:
            return                                # accepted; nothing persists in the emulator
        self._values[key] = value
        if entry.index == od.CONTROLWORD:
            self._on_controlword(int(value))
        elif entry.index == od.MODES_OF_OPERATION:
            self._on_mode(int(value))
        elif entry.index == od.PRODUCER_HEARTBEAT_TIME:
            self._next_heartbeat = None
        elif entry.index == od.CONSUMER_HEARTBEAT_TIME:
            self._consumer_last = None
        else:
            self.pdos.stored(entry.index)
