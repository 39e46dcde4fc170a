"""The motor driver's start-up and shutdown sequences: the steps of `startup.py` run against the
drive (NMT, SDO), their answers, retries and failures (a mixin of `driver.MotorDriver`, its state)."""

from __future__ import annotations

import struct

import can

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_objects import Command, NmtCommand
from hopper_ros.canbus.cia301.master import SdoError, SdoTransfer, nmt_frame, sync_frame

from . import startup
from .cia402 import DISABLED_STATES
from .settings import ERROR, INFO, WARN
from .status import Phase


class StartupAndShutdown:
    """`shutdown()`, `begin_shutdown()` and the sequence steps `MotorDriver.cycle()` advances."""

    def shutdown(self, timeout: float | None = None) -> bool:
        """Bring the drive to a safe stop, pumping the bus; True if the drive confirmed it is disabled.

        Power stage off (controlword "disable voltage" by PDO while running, then by SDO), the
        statusword read back, the drive's consumer of our heartbeat switched off, NMT
        pre-operational (no more PDOs). Bounded by `timeout` (default settings.shutdown_timeout).
        """
        timeout = self.settings.shutdown_timeout if timeout is None else timeout
        self.begin_shutdown()
        deadline = self.clock() + timeout
        next_cycle = self.clock()
        while self.phase is not Phase.STOPPED:
            now = self.clock()
            if now >= deadline:
                break
            if now >= next_cycle:
                self.cycle()
                next_cycle += self.settings.sync_period
                continue
            try:
                frame = self.bus.recv(timeout=min(next_cycle, deadline) - now)
            except (can.CanError, OSError) as exc:
                self._bus_error(self.clock(), f"receive failed: {exc}")
                frame = None
            if frame is not None:
                self.handle(frame)
        if self.phase is not Phase.STOPPED:
            self.sdo.abort()
            self._send(self._rpdo_frame(1, Command.DISABLE_VOLTAGE))   # last word, even unconfirmed
            self._send(nmt_frame(NmtCommand.ENTER_PRE_OPERATIONAL, self.node_id))
            self.phase = Phase.STOPPED
            self._event(ERROR, "shutdown: the drive did not confirm it is disabled")
        return self._shutdown_confirmed

    def begin_shutdown(self) -> None:
        """Start the shutdown sequence; `cycle()` and `handle()` carry it out (see `shutdown`)."""
        if self.phase in (Phase.SHUTTING_DOWN, Phase.STOPPED):
            return
        was_running = self.phase is Phase.RUNNING
        self.sdo.abort()
        self._want_enabled, self._quick_stop = False, False
        self._shutdown_confirmed = False
        self.phase = Phase.SHUTTING_DOWN
        self._steps = startup.shutdown_steps(self.clock() + 0.05 if was_running else None, self.settings,
                                             self._check_disabled)

    @property
    def shutdown_confirmed(self) -> bool:
        """The drive confirmed (statusword) that its power stage is off, during the shutdown."""
        return self._shutdown_confirmed

    def _begin_startup(self, now: float) -> None:
        self.sdo.abort()
        self._startup_answered = False
        self.phase = Phase.STARTING
        self._sync_outstanding = False
        self._reset.arm()
        self.status.state = None
        self._steps = startup.startup_steps(self.drive, self.settings, self._check_device_type, self._record_error_code)

    def _advance(self, now: float) -> None:
        """Run the sequence's steps until one waits for the drive (an SDO in flight)."""
        while self._steps and not self.sdo.busy and self.phase in (Phase.STARTING, Phase.SHUTTING_DOWN):
            step = self._steps[0]
            kind = step[0]
            if kind == "pdo_disable":
                if self.status.state in DISABLED_STATES or now >= step[1] or not self.heartbeat.alive:
                    self._shutdown_confirmed = self.status.state in DISABLED_STATES
                    self._steps.pop(0)
                    continue
                return                              # cycle() keeps sending "disable voltage"
            self._steps.pop(0)
            if kind == "nmt":
                self._send(nmt_frame(step[1], self.node_id))
                if step[1] == NmtCommand.START:
                    self._nmt_start_sent_at = now
            elif kind == "download":
                _, index, sub, fmt, value = step
                self.sdo.download(index, sub, struct.pack(fmt, value), now, tag=step)
            elif kind == "upload":
                self.sdo.upload(step[1], step[2], now, tag=step)
            elif kind == "running":
                self.phase = Phase.RUNNING
                self.waiting_for_drive = False
                self.heartbeat.arm(now)
                self._event(INFO, f"drive {self.node_id} configured and started (NMT operational, "
                                  f"SYNC every {self.settings.sync_period * 1e3:g} ms)")
            elif kind == "stopped":
                self.phase = Phase.STOPPED
                self._event(INFO, "shutdown: drive disabled, NMT pre-operational" if self._shutdown_confirmed
                            else "shutdown: NMT pre-operational, drive state not confirmed")

    def _sdo_done(self, transfer: SdoTransfer, now: float) -> None:
        tag = transfer.tag
        if transfer.error is not None:
            if not transfer.error.timed_out:
                self.counters["sdo_aborts"] += 1
            if self.phase is Phase.STARTING:
                if transfer.error.timed_out and not self._startup_answered:
                    self._wait_for_drive(now)
                else:
                    self._startup_failed(now, str(transfer.error))
            elif self.phase is Phase.SHUTTING_DOWN:
                self._event(WARN, f"shutdown: {transfer.error}")
                self._advance(now)
            else:
                self._event(WARN, str(transfer.error))
            return
        if self.phase is Phase.STARTING:
            self._startup_answered = True
        if isinstance(tag, tuple) and tag and tag[0] == "error_code":
            self._record_error_code(transfer)
        elif isinstance(tag, tuple) and tag and tag[0] == "upload":
            try:
                tag[3](transfer)
            except (SdoError, ValueError) as exc:
                if self.phase is Phase.STARTING:
                    self._startup_failed(now, str(exc))
                    return
                self._event(WARN, str(exc))
        self._advance(now)

    def _wait_for_drive(self, now: float) -> None:
        """The drive does not answer at all (yet): not an error until it answers wrongly."""
        if not self.waiting_for_drive:
            self._event(WARN, f"drive {self.node_id} does not answer (yet): trying every "
                              f"{self.settings.startup_retry:g} s")
        self.waiting_for_drive = True
        self.phase = Phase.FAILED
        self._retry_at = now + self.settings.startup_retry
        self._steps = []

    def _startup_failed(self, now: float, reason: str) -> None:
        self.waiting_for_drive = False
        self.counters["startup_failures"] += 1
        repeated = reason == self.startup_error
        self.startup_error = reason
        self.phase = Phase.FAILED
        self._retry_at = now + self.settings.startup_retry
        self._steps = []
        if not repeated:
            self._event(ERROR, f"drive start-up failed: {reason}; retrying every {self.settings.startup_retry:g} s")

    def _check_device_type(self, transfer: SdoTransfer) -> None:
        startup.check_device_type(self.node_id, transfer)

    def _record_error_code(self, transfer: SdoTransfer) -> None:
        code = transfer.value("<H")
        if code:
            self._set_fault(code)
            self._event(WARN, f"drive reports error 0x{code:04X}: {self.status.fault_text}")

    def _check_disabled(self, transfer: SdoTransfer) -> None:
        state = eo.decode_statusword(transfer.value("<H"))
        self._shutdown_confirmed = state in DISABLED_STATES
        self._event(INFO if self._shutdown_confirmed else ERROR, f"shutdown: drive state {state.value}")

    def _shutdown_cycle(self, now: float) -> None:
        if self._steps and self._steps[0][0] == "pdo_disable":
            self._send_rpdo(now, force=False)
            self._sent_since_sync = None
            if self._send(sync_frame()):
                self.counters["sync_sent"] += 1
        self._advance(now)
