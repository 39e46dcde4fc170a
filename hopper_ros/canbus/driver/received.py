"""The motor driver's handling of received frames: TPDOs (status), SDO answers, EMCY, heartbeats,
and the drive's CiA 402 state changes they report (a mixin of `driver.MotorDriver`, its state)."""

from __future__ import annotations

import can

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_objects import NmtCommand, NmtState, State
from hopper_ros.canbus.cia301.master import MalformedFrame, decode_emcy, nmt_frame, nmt_state_name

from .cia402 import FAULT_STATES
from .settings import ERROR, INFO, MODE_DISABLED, WARN
from .startup import TPDO_MAPPINGS
from .status import Phase


class ReceivedFrames:
    """`handle(frame)` and what each received frame does to `MotorDriver`'s state."""

    def handle(self, frame: can.Message) -> bool:
        """Take one received frame; True when it completed the TPDOs of a SYNC (new status)."""
        now = self.clock()
        self.counters["frames_received"] += 1
        if frame.is_error_frame:
            self._bus_error(now, "error frame received")
            return False
        if frame.is_extended_id or frame.is_remote_frame:
            return False
        handler = self._cob.get(frame.arbitration_id)
        if handler is None:
            return False
        try:
            return bool(handler(bytes(frame.data), now))
        except MalformedFrame as exc:
            self.counters["malformed_frames"] += 1
            self._event(WARN, f"malformed frame 0x{frame.arbitration_id:03X} [{bytes(frame.data).hex()}]: {exc}",
                        key="malformed")
            return False

    def _on_tpdo1(self, data: bytes, now: float) -> bool:
        statusword, position, current_ma = TPDO_MAPPINGS[1].decode(data)
        status = self.status
        state = eo.decode_statusword(statusword)
        if state != status.state:
            self._on_state_change(status.state, state, now)
        status.stamp, status.statusword, status.state = now, statusword, state
        status.position = self.units.angle(position)
        status.current = current_ma / 1000.0
        status.torque = self.units.torque(status.current)
        status.commanded_mode = self._mode if (self._want_enabled and state is State.OPERATION_ENABLED) else MODE_DISABLED
        return self._tpdo_received(1, now)

    def _on_tpdo2(self, data: bytes, now: float) -> bool:
        rpm, mode, error_code = TPDO_MAPPINGS[2].decode(data)
        status = self.status
        status.velocity = self.leg_rate_for_rpm(rpm)
        status.operation_mode = mode
        if error_code and error_code != status.fault_code:
            self._set_fault(error_code)
        return self._tpdo_received(2, now)

    def _tpdo_received(self, number: int, now: float) -> bool:
        self.counters["tpdo_received"] += 1
        if number == 1:
            self.stillness.on_answer(now)        # every SYNC is answered by each TPDO (transmission type 1)
        self._tpdo_seen |= 1 << (number - 1)
        if self._sync_outstanding and self._tpdo_seen == (1 << len(TPDO_MAPPINGS)) - 1:
            self._sync_outstanding = False
            self._last_answer = now
            return True
        return False

    def _on_sdo(self, data: bytes, now: float) -> bool:
        try:
            transfer = self.sdo.on_frame(data)
        except MalformedFrame as exc:
            if exc.transfer is not None:
                self._sdo_done(exc.transfer, now)
            raise
        if transfer is not None:
            self._sdo_done(transfer, now)
        return False

    def _on_emcy(self, data: bytes, now: float) -> bool:
        emergency = decode_emcy(data)
        self.counters["emcy_received"] += 1
        if emergency.is_reset:
            self._event(INFO, "drive EMCY: error reset")
        else:
            self._set_fault(emergency.code)
            self._event(ERROR, f"drive EMCY 0x{emergency.code:04X}: {emergency.text} "
                               f"(error register 0x{emergency.register:02X})")
        return False

    def _on_heartbeat(self, data: bytes, now: float) -> bool:
        was_alive = self.heartbeat.alive and self.heartbeat.last_seen is not None
        state = self.heartbeat.on_frame(data, now)
        self.status.nmt_state = state
        self.status.heartbeat_ok = True
        if not was_alive and self.heartbeat.last_seen is not None and self.counters["heartbeat_losses"]:
            self._event(INFO, f"drive heartbeat back ({nmt_state_name(state)})")
        if state == NmtState.BOOTUP:
            self.counters["drive_bootups"] += 1
            if self.phase in (Phase.RUNNING, Phase.FAILED):
                self._event(WARN, "drive rebooted: configuring it again")
                self._begin_startup(now)
        elif (self.phase is Phase.RUNNING and state != NmtState.OPERATIONAL
              and now - self._nmt_start_sent_at > self.heartbeat_period):
            self._event(WARN, f"drive in NMT {nmt_state_name(state)}: starting it again")
            self._nmt_start_sent_at = now
            self._send(nmt_frame(NmtCommand.START, self.node_id))
        return False

    def _set_fault(self, code: int) -> None:
        self.status.fault_code = code
        self.status.fault_text = eo.error_text(code)

    def _on_state_change(self, old: State | None, new: State, now: float) -> None:
        self._event(INFO, f"drive state {old.value if old else 'UNKNOWN'} -> {new.value}")
        if new in FAULT_STATES and old not in FAULT_STATES:
            self.counters["faults"] += 1
            self._reset.edges = 0
            if old is not None or not self._reset.armed:
                self._reset.armed = False    # a fault in operation waits for an acknowledgement
            if not self.status.fault_code:
                self._request_error_code()
            self._event(ERROR, "drive fault" + (f" 0x{self.status.fault_code:04X}: {self.status.fault_text}"
                                                if self.status.fault_code else "") + ": drive disabled")
        elif old in FAULT_STATES and new not in FAULT_STATES:
            self.counters["fault_resets"] += 1
            self._reset.disarm()
            self._event(INFO, "drive fault reset")

    def _request_error_code(self) -> None:
        if self.phase is Phase.RUNNING and not self.sdo.busy:
            self.sdo.upload(eo.ERROR_CODE, 0, self.clock(), tag=("error_code",))
