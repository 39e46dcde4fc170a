"""The hip motor driver: CANopen master of the maxon EPOS2, as plain Python (no ROS).

`MotorDriver(bus, hardware, settings, clock)` owns one python-can bus and one drive (node id from
config/hardware.yaml). The caller drives it (`cycle.CycleLoop` does, for the node):

- `cycle()` once per `settings.sync_period` (1 ms): timeouts (SDO, heartbeat, command watchdog),
  the start-up sequence, the CiA 402 controlword, the RPDO and the SYNC, our own heartbeat;
- `handle(frame)` for every received frame (TPDOs, SDO answers, EMCY, heartbeats); never raises:
  a malformed frame is counted (`counters["malformed_frames"]`) and ignored;
- `command(mode, setpoint)` for each motor command (MotorCommand.MODE_*: 0 disabled, 1 hip
  torque [N m], 2 leg angle [rad], 3 the stance ramp); the RPDO goes out at once when the drive
  is running;
- `shutdown()` at the end: power stage off (confirmed by the drive), our heartbeat consumer in the
  drive switched off, NMT pre-operational. It pumps the bus itself.

The start-up sequence and the PDO layout: `startup.py`, run by `sequence.py`; received frames:
`received.py`; the CiA 402 walk: `cia402.py`; units: `units.py`; status and phase: `status.py`. Exactly one RPDO per SYNC period unless commands arrive faster.

Safety: the drive is enabled only while valid commands keep arriving (`command_timeout`; a stale
stream ends with the current setpoint zeroed and a quick stop in the same RPDO, then disable
voltage as soon as the drive reports QUICK STOP ACTIVE, `quick_stop_time` after the trip at the
latest), the drive's heartbeat is alive and the bus has
been free of errors for `bus_error_holdoff`. A fault is reset at start-up and after the command
stream acknowledged it with a disable command. Units: SI at this module's edges, drive units
(mA, qc, rpm) only in the frames.
"""

from __future__ import annotations

import math
import time
from typing import Callable

import can

from hopper_ros.canbus import epos2_objects as eo
from hopper_ros.canbus.epos2_objects import Command, OperationMode, State
from hopper_ros.canbus.cia301.master import HeartbeatConsumer, SdoClient, heartbeat_frame, sync_frame
from hopper_ros.runtime.gaps import GapHistogram
from hopper_ros.hardware.config import HardwareConfig
from hopper_ros.physics.laws import mean_ramp_torque, ramp_impulse

from . import cia402
from .cia402 import FAULT_STATES, FaultReset
from .received import ReceivedFrames
from .sequence import StartupAndShutdown
from .skipped import SentTorque, SkippedImpulse
from .settings import (COUNTER_NAMES, ERROR, INFO, MODE_CURRENT, MODE_DISABLED, MODE_NAMES, MODE_POSITION, MODE_RAMP,
                       WARN, DriveConfig, DriverSettings)
from .startup import RPDO_MAPPINGS, TPDO_MAPPINGS
from .stillness import FROZEN_MIN, STAMP_SHIFT_KEPT, DriveStillness
from .status import DriveStatus, Phase, connection_closed, first_line
from .units import DriveUnits

__all__ = ["MotorDriver", "DriveStatus", "Phase", "connection_closed", "first_line", "RAMP_RESTAMP"]

RAMP_RESTAMP = 0.0005   # [s] a MODE_RAMP stamp moved by more than this re-anchors the running ramp (repeats of
                        #   one stamp differ by the command's transit jitter only)
HOLD_BOOKED = 1.5       # [SYNC periods] a touchdown's setting held longer than this is booked (MotorDriver._book_hold)


class MotorDriver(ReceivedFrames, StartupAndShutdown):
    """CANopen master of one EPOS2 (see the module docstring). Not thread-safe: one caller at a time."""

    def __init__(self, bus: can.BusABC, hardware: HardwareConfig | DriveConfig,
                 settings: DriverSettings = DriverSettings(), clock: Callable[[], float] = time.monotonic):
        self.bus = bus
        self.settings = settings
        self.clock = clock
        self.drive = hardware if isinstance(hardware, DriveConfig) else DriveConfig.from_hardware(hardware)
        self.units = DriveUnits(self.drive)
        self.motor, self.encoder = self.drive.motor, self.drive.encoder
        self.node_id = self.drive.node_id
        self.current_limit = self.drive.current_limit
        self.heartbeat_period = self.drive.heartbeat_period
        if not 0 < self.heartbeat_period < settings.heartbeat_timeout:
            raise ValueError("drive.heartbeat_period must be positive and below the heartbeat timeout")
        eo.tpdo_cob_id(1, self.node_id)  # validates the node id
        if settings.master_node_id == self.node_id:
            raise ValueError(f"motor_driver: master_node_id {settings.master_node_id} is the drive's node id")
        self.counters = dict.fromkeys(COUNTER_NAMES, 0)
        self.ramp_late_max = 0.0            # [s] the most of a ramp skipped because it came after its start
        self.events: list[tuple[int, str]] = []     # (level, text) for the caller's log; drained by it
        self._event_times: dict[str, float] = {}
        self.status = DriveStatus()
        self.phase = Phase.STARTING
        self.startup_error = ""
        self.waiting_for_drive = False              # start-up: the drive has not answered any SDO yet
        self._startup_answered = False
        self.sdo = SdoClient(self.node_id, self._send, settings.sdo_timeout)
        self.heartbeat = HeartbeatConsumer(self.node_id, settings.heartbeat_timeout)
        self._cob = {
            eo.tpdo_cob_id(1, self.node_id): self._on_tpdo1,
            eo.tpdo_cob_id(2, self.node_id): self._on_tpdo2,
            eo.sdo_tx_cob_id(self.node_id): self._on_sdo,
            eo.emcy_cob_id(self.node_id): self._on_emcy,
            eo.heartbeat_cob_id(self.node_id): self._on_heartbeat,
        }
        self._rpdo_cob = {n: eo.rpdo_cob_id(n, self.node_id) for n in RPDO_MAPPINGS}
        now = clock()
        # command and safety state
        self._mode = MODE_DISABLED          # last valid command's mode
        self._current_ma = 0                # its drive setpoints
        self._position_qc = 0
        self._last_command: float | None = None
        self.command_gaps = GapHistogram()
        self.transport_lost = False         # the connection to the bus closed for good (the socketcand hub went away)
        self._want_enabled = False
        self._quick_stop = False
        self._watchdog_at = -math.inf       # when the command watchdog last tripped
        self._bus_error_at: float | None = None
        self._reset = FaultReset(settings.fault_reset_attempts, settings.fault_reset_interval)   # armed: a
        self._last_cw: int | None = None                                  # fault found at start-up is reset
        # cyclic exchange
        self._sent_since_sync: tuple[int, bytes] | None = None
        # MODE_RAMP: (tau_0, duration, start, stamp): start = the stamp (or later) + the time the robot stood still
        self._ramp: tuple[float, float, float, float] | None = None
        self._interrupted: tuple[float, float, float, float] | None = None   # the ramp a watchdog stop ended
        self._ramp_torque = 0.0             # [N m] the latest ramp setting
        self._sent_torque = SentTorque()    # what the drive was sent for the present ramp (a late start owes the rest)
        self._skipped = SkippedImpulse(abs(self.units.torque(self.units.current_limit - 0.001)),   # 1 mA inside
                                       settings.sync_period)
        # the ramp setting the drive holds until the next RPDO: (sent at, the ramp's part of it [N m], the ramp's start
        # it was chosen for)
        self._hold: tuple[float, float, float] | None = None
        self._ramp_part = 0.0               # [N m] the ramp's part of the latest setting (the rest gives what is owed)
        self._last_rpdo: tuple[int, bytes] | None = None   # the last RPDO sent and when
        self._last_rpdo_time = -math.inf
        self._tpdo_seen = 0                 # TPDOs received since the last SYNC (bit n-1: TPDO n)
        self._sync_outstanding = False
        self.stillness = DriveStillness(settings.sync_period, now)   # when the robot stood still
        self._held = 0.0                    # [s] what the ramp moved by for the latest stand-still so far
        self._follows = False               # the ramp moves with the latest stand-still (it came after its stamp)
        self._clock_offset: float | None = None   # [s] the sensing clock mapping of the latest command's stamp
        self._stamp_shift = 0.0   # [s] the sensing clock's re-anchors the drive's answers did not bear out, taken off stamps
        self._shifted_at = -math.inf   # when it last grew (kept STAMP_SHIFT_KEPT at most without the step back)
        self._last_answer = now             # when the drive last answered a SYNC (its TPDOs complete)
        self._next_master_heartbeat = now
        self._nmt_start_sent_at = -math.inf
        # start-up / shutdown sequence
        self._steps: list[tuple] = []
        self._retry_at = now
        self._shutdown_confirmed = False
        self._begin_startup(now)

    # ================================================================== public API

    def command(self, mode: int, setpoint: float, duration: float = 0.0, age: float = 0.0,
                clock_offset: float = math.nan) -> bool:
        """Take one motor command; False (counted, ignored) if it is invalid.

        MODE_RAMP: the stance ramp of (2.32), hip torque -setpoint (1 - t/duration) for t in
        [0, duration) from `age` seconds ago (its stamp: the touchdown), then 0; a negative age is a
        ramp scheduled ahead (a predicted touchdown: zero current until then). The driver's own
        1 kHz cycle computes the current of every period, so jitter in the command stream does
        not stretch or shift the ramp; repeats of the same ramp keep its start, and the same ramp
        under a stamp more than RAMP_RESTAMP away (the measured touchdown) moves to that stamp.

        `clock_offset` [s]: the sensing clock's mapping the stamps are on (host minus robot time,
        MotorCommand.clock_offset). When it steps by a stand-still's worth, the sensing clock has
        re-anchored by the robot's stand-still: the stamps carry it from then on, and the time the
        drive's answers said the robot stood still moves no ramp any more (`DriveStillness.reflect`).
        """
        now = self.clock()
        if mode == MODE_RAMP and not (math.isfinite(duration) and duration > 0.0 and math.isfinite(age)):
            mode = -1                                       # rejected below
        if mode not in MODE_NAMES or (mode != MODE_DISABLED and not math.isfinite(setpoint)):
            self.counters["commands_rejected"] += 1
            self._event(WARN, f"rejected motor command: mode {mode}, setpoint {setpoint!r}", key="rejected")
            return False
        self.counters["commands_received"] += 1
        self._note_clock(clock_offset, now)
        if self._last_command is not None:
            self.command_gaps.add(now - self._last_command)
        self._last_command = now
        self._mode = mode
        if mode == MODE_DISABLED:
            self._want_enabled = False
            self._quick_stop = False
            self._interrupted = None
            if self.status.state in FAULT_STATES and not self._reset.armed:
                self._reset.arm()                       # the command stream acknowledges the fault
        else:
            self._want_enabled, self._quick_stop = True, False
            if mode == MODE_CURRENT:
                self._current_ma = self._current_setting(setpoint)
            elif mode == MODE_RAMP:
                stamp = now - age - self._stamp_shift  # the command's stamp on this clock
                if self._ramp is None and self._interrupted and self._interrupted[:2] == (setpoint, duration):
                    self._ramp = self._interrupted     # a ramp the watchdog stopped goes on at its own phase
                if self._ramp is None or self._ramp[:2] != (setpoint, duration):
                    # anchored at its stamp (the touchdown, or one predicted ahead: zero current until
                    # then), unless the command came late: a ramp skipped is energy lost
                    start = max(stamp + self.frozen_after(stamp, now), now - self.settings.max_ramp_age)
                    self._ramp = (setpoint, duration, start, stamp)
                    self._sent_torque.reset()
                    self._held = self.stillness.pending(now, stamp)
                    self._follows = self.stillness.covers(stamp)
                    self._note_late_ramp(now, start, "the command came after its touchdown")
                elif abs(stamp - self._ramp[3]) > RAMP_RESTAMP:
                    # the same ramp under a new stamp (the measured touchdown after a predicted one)
                    counted = self._ramp[2]
                    self._ramp = (setpoint, duration, stamp + self.frozen_after(stamp, now), stamp)
                    self._held = self.stillness.pending(now, stamp)
                    self._follows = self.stillness.covers(stamp)
                    unanswered = self.stillness.unanswered_span(now)     # the last silence (to now in one)
                    if counted > now or (self._ramp[2] < counted and counted >= unanswered[1]
                                         and not self._sent_torque.held_at(unanswered[1])):
                        # not begun, or begun after the touchdown where a stand-still's count put it, the drive
                        # answering again and its robot woken to no ramp torque: what the ramp owes from its new
                        # start is less what the drive was sent since. Not otherwise: what the robot took is then
                        # not what the host's clock says (a ramp begun before a stand-still was sent its first
                        # part before the re-anchored stamp; a robot woken to a ramp's setting ran on it while it
                        # caught up its world), and owed again it was paid twice
                        why = ("the touchdown came before its prediction" if counted > now else
                               "the touchdown came before the start the stand-still's count gave it")
                        self._note_late_ramp(now, self._ramp[2], why,
                                             self._sent_torque.between(self._ramp[2], now, unanswered))
                self._current_ma = self._current_setting(self._ramp_setting(now))
            else:
                self._position_qc = self._position_setting(setpoint)
            if mode != MODE_RAMP:
                self._ramp = None
            self._interrupted = None
        if self.phase is Phase.RUNNING:
            self._send_rpdo(now, force=True)
        return True

    def cycle(self) -> None:
        """One SYNC period: timeouts, start-up progress, controlword, RPDO, SYNC, heartbeat."""
        now = self.clock()
        self._produce_heartbeat(now)
        transfer = self.sdo.poll(now)
        if transfer is not None:
            self.counters["sdo_timeouts"] += 1
            self._sdo_done(transfer, now)
        if self.heartbeat.check(now):
            self.counters["heartbeat_losses"] += 1
            self.status.heartbeat_ok = False
            self._event(ERROR, f"drive heartbeat lost (none for {self.settings.heartbeat_timeout * 1e3:.0f} ms): "
                               "drive disabled")
        if self.phase is Phase.FAILED and now >= self._retry_at:
            self._begin_startup(now)
        if self.phase is Phase.STARTING:
            self._advance(now)
            return
        if self.phase is Phase.SHUTTING_DOWN:
            self._shutdown_cycle(now)
            return
        if self.phase is not Phase.RUNNING:
            return
        self._trip_watchdog(now)
        if self._sync_outstanding and self._tpdo_seen != (1 << len(TPDO_MAPPINGS)) - 1:
            self.counters["tpdo_missed"] += 1
        self._follow_stillness(now)
        self._send_rpdo(now, force=False)
        self._sent_since_sync = None
        self._tpdo_seen = 0
        if self._send(sync_frame()):
            self.counters["sync_sent"] += 1
            self.stillness.sent += 1
            self._sync_outstanding = True

    def watchdog_deadline(self) -> float:
        """When the command watchdog trips unless a valid command comes first (inf: not armed)."""
        if self.phase is Phase.RUNNING and self._want_enabled and self._last_command is not None:
            return self._last_command + self.settings.command_timeout
        return math.inf

    def watchdog(self) -> bool:
        """Trip the command watchdog now if it is due (the RPDO goes out at once); True if it tripped.

        `cycle()` checks it every SYNC period; a caller that waits between cycles calls this at
        `watchdog_deadline()` so the trip is not up to a period late."""
        now = self.clock()
        if self.phase is not Phase.RUNNING or not self._trip_watchdog(now):
            return False
        self._send_rpdo(now, force=True)
        return True

    def _trip_watchdog(self, now: float) -> bool:
        if not (self._want_enabled and now - self._last_command > self.settings.command_timeout):
            return False
        self._want_enabled, self._quick_stop = False, True
        self._watchdog_at = now
        self._current_ma, self._ramp, self._interrupted = 0, None, self._ramp   # the current zeroed at once
        self._hold = None
        self.counters["watchdog_stops"] += 1
        self._event(WARN, f"no motor command for {(now - self._last_command) * 1e3:.1f} ms: current zeroed, "
                          "quick stop, then disable")
        return True

    @property
    def enabled(self) -> bool:
        return self.status.state is State.OPERATION_ENABLED

    def health(self) -> tuple[int, str]:
        """(level, message) of the driver's present condition: OK/WARN/ERROR and words."""
        now = self.clock()
        status = self.status
        if self.phase is Phase.FAILED:
            if self.waiting_for_drive:
                return WARN, f"waiting for drive {self.node_id} to answer"
            return ERROR, f"start-up failed: {self.startup_error}"
        if self.phase is Phase.STARTING:
            return WARN, "starting: configuring the drive"
        if self.phase in (Phase.SHUTTING_DOWN, Phase.STOPPED):
            return WARN, "shut down: drive disabled" if self._shutdown_confirmed else "shutting down"
        if not self.heartbeat.alive:
            return ERROR, "drive heartbeat lost: drive disabled"
        if status.state in FAULT_STATES:
            return ERROR, f"drive fault 0x{status.fault_code:04X}: {status.fault_text}"
        if self._bus_error_recent(now):
            return ERROR, "CAN bus error: drive disabled"
        if self._quick_stop or (self._last_command is not None and self._mode != MODE_DISABLED
                                and not self._want_enabled):
            return WARN, "command timeout: drive stopped"
        return INFO, ""

    # ================================================================== conversions

    def current_for_torque(self, torque: float) -> tuple[float, bool]:
        """Motor current [A] for a hip torque [N m], clamped to the current limit; (current, clamped)."""
        return self.units.current_for_torque(torque)

    def _current_setting(self, torque: float) -> int:
        milliamps, clamped = self.units.current_setting(torque)
        if clamped:
            self.counters["current_clamped"] += 1
        return milliamps

    def counts_for_angle(self, angle: float) -> int:
        """Motor encoder count [qc] at a leg angle [rad] (nearest count)."""
        return self.units.counts_for_angle(angle)

    def _position_setting(self, angle: float) -> int:
        return self.units.position_setting(angle)

    def leg_rate_for_rpm(self, rpm: float) -> float:
        """Leg angular velocity [rad/s] for a motor speed [rpm] (inverse of HipMotor.motor_speed_rpm)."""
        return self.units.leg_rate_for_rpm(rpm)

    # ================================================================== frames out

    def _send(self, frame: can.Message) -> bool:
        try:
            self.bus.send(frame, timeout=self.settings.sync_period)
        except (can.CanError, OSError) as exc:
            self.transport_lost = self.transport_lost or connection_closed(exc)
            self._bus_error(self.clock(), f"send of 0x{frame.arbitration_id:03X} failed: {first_line(exc)}")
            return False
        self.counters["frames_sent"] += 1
        return True

    def bus_error(self, text: str, exc: BaseException | None = None) -> None:
        """Report a bus failure the caller saw (e.g. receiving failed): counted, drive disabled."""
        self.transport_lost = self.transport_lost or (exc is not None and connection_closed(exc))
        self._bus_error(self.clock(), text)

    def _bus_error(self, now: float, text: str) -> None:
        self.counters["bus_errors"] += 1
        if not self._bus_error_recent(now):
            self._event(ERROR, f"CAN bus error: {text}: drive disabled")
        self._bus_error_at = now

    def _bus_error_recent(self, now: float) -> bool:
        return self._bus_error_at is not None and now - self._bus_error_at < self.settings.bus_error_holdoff

    def _produce_heartbeat(self, now: float) -> None:
        period = self.settings.master_heartbeat_period
        if period and self.phase is not Phase.STOPPED and now >= self._next_master_heartbeat:
            self._next_master_heartbeat = max(self._next_master_heartbeat + period, now)
            self._send(heartbeat_frame(self.settings.master_node_id))

    def _enable_allowed(self, now: float) -> bool:
        return (self.phase is Phase.RUNNING and self.heartbeat.alive and self.heartbeat.last_seen is not None
                and not self._bus_error_recent(now))

    def _controlword(self, now: float) -> int:
        """The controlword for this instant: CiA 402 transitions towards the target state (cia402)."""
        allowed = self._enable_allowed(now)
        return cia402.controlword(
            self.status.state, enable=self._want_enabled and allowed,
            quick_stop=self._quick_stop and allowed and now - self._watchdog_at < self.settings.quick_stop_time,
            fault_reset=lambda: self._fault_reset_word(now) if self.phase is Phase.RUNNING else Command.DISABLE_VOLTAGE)

    def _fault_reset_word(self, now: float) -> int:
        """Rising edges of bit 7, `fault_reset_interval` apart, while a reset is armed."""
        word, gave_up = self._reset.word(now, self._last_cw)
        if gave_up:
            self._event(ERROR, f"fault reset failed after {self._reset.edges} attempts: "
                               "command disable to try again", key="reset_failed")
        return word

    @property
    def silent(self) -> bool:
        """The drive answers no SYNC (stillness.SILENT_PERIODS), or did until its count settled: the robot
        may be standing still, for a time not known yet. Until the count, the first answers after a stop
        (the ones the hub held) make a stand-still look short: the controller, told the silence was over
        but not yet how long, cancelled a ramp whose touchdown the stand-still had put off (bench round 5)."""
        return self.stillness.silent or self.stillness.settling

    @property
    def frozen_time(self) -> float:
        """[s] The time the robot stood still so far (SYNCs its drive never answered)."""
        return self.stillness.frozen_time

    def frozen_so_far(self, now: float | None = None) -> float:
        """[s] `frozen_time` and the latest stand-still not yet settled (what the controller's grace
        for a touchdown moves by)."""
        return self.stillness.frozen_time + self.stillness.pending(self.clock() if now is None else now)

    def frozen_after(self, stamp: float, now: float) -> float:
        """[s] How long the robot stood still after the instant `stamp` (`DriveStillness.frozen_after`)."""
        return self.stillness.frozen_after(stamp, now)

    def _note_clock(self, clock_offset: float, now: float) -> None:
        """The commands' stamps re-anchored by a stand-still's worth (FROZEN_MIN or more). Where the drive's answers
        say the robot stood still lately, its stand-still is in the stamps now (a ramp's command on the new mapping
        moves it there) and the answers' count of it moves nothing. A step later where the drive answered every SYNC:
        the robot ran on, the sensing host read its packets late (a container starved for 20-30 ms under normal
        scheduling, catching up slowly); the step is taken off the stamps, so that the measured touchdown does not
        move the ramp by it (bench_demo_load, normal scheduling: a ramp 11 ms late, the apex 1.65 cm off), until a
        step earlier (packets earlier than the mapping allowed: proof) takes it back."""
        if self._stamp_shift and now - self._shifted_at > STAMP_SHIFT_KEPT:
            self._event(INFO, f"the sensing clock's step of {self._stamp_shift * 1e3:.1f} ms was not taken back within "
                              f"{STAMP_SHIFT_KEPT:.1f} s: the robot stood still after all (no SYNC of it to leave "
                              "unanswered); the stance ramp follows the stamps", key="shift_dropped")
            self._stamp_shift = 0.0
        if not math.isfinite(clock_offset):
            return
        step = 0.0 if self._clock_offset is None else clock_offset - self._clock_offset
        self._clock_offset = clock_offset
        if abs(step) < FROZEN_MIN:
            return
        if step > 0.0 and not self.stillness.stood_still_lately(now):
            self._stamp_shift += step
            self._shifted_at = now
            self._event(INFO, f"the sensing clock re-anchored by {step * 1e3:.1f} ms while the drive answered every "
                              "SYNC (the robot ran on: its packets were read late): the stance ramp keeps the drive's "
                              "time", key="reanchor")
            return
        if step < 0.0:       # packets earlier than the mapping allowed: proof, and the end of any lateness taken off
            self._stamp_shift = max(0.0, self._stamp_shift + step)
        self.stillness.reflect()
        self._held, self._follows = 0.0, False
        self._event(INFO, f"the sensing clock re-anchored by {step * 1e3:.1f} ms (the robot stood still?): the "
                          "stance ramp follows the stamps", key="reanchor")

    def _follow_stillness(self, now: float) -> None:
        """The ramp is the robot's: while it stands still the ramp waits (its start moves with the
        clock) instead of running out in a stance that is frozen, and one scheduled ahead of a
        predicted touchdown moves with the robot's flight. When the answers are back, the SYNCs left
        unanswered say how long it stood still and the ramp follows that, whatever it was held (a robot
        whose answers were only late ran on: its ramp goes back to the host clock)."""
        silence = self.stillness.standing_still(now)
        settled = self.stillness.update(now)
        if self._ramp is None:
            self._follows, self._held = False, 0.0
        elif self.stillness.silent and not self.stillness.reflected:
            self._follows = True                    # a ramp of this silence moves with it
        if settled is not None:
            target = settled if self._follows else 0.0
        else:
            target = max(silence, self._held) if self._follows else self._held
        move = target - self._held
        if self._ramp is not None and move:
            tau_0, duration, start, stamp = self._ramp
            self._ramp = (tau_0, duration, start + move, stamp)
            self.counters["ramp_held_syncs"] += move > 0.0
            self._hold = None               # the robot stood still meanwhile: what it was given is not known
        self._held = 0.0 if settled is not None else target
        if settled is not None:
            self._follows = False
        if settled:
            began, ended = self.stillness.silence_span
            self._event(WARN, f"the drive stood still for {settled * 1e3:.0f} ms ({settled / self.settings.sync_period:.0f} "
                              f"SYNCs never answered, no answer for {(ended - began) * 1e3:.1f} ms: the "
                              "simulated robot's process stopped?): the stance ramp moved by that")

    def _note_late_ramp(self, now: float, start: float, why: str, given: float = 0.0) -> None:
        """A ramp whose start had passed when it reached the driver: the impulse of its first `now - start`,
        less what the drive was `given` since the start [N m s], is given as the current limit allows
        (skipped.py). More than a SYNC period's worth missed is counted and said, so that a stride that misses
        its apex shows where its torque was late."""
        tau_0, duration = float(self._ramp[0]), float(self._ramp[1])
        self._skipped.begin(now - start, tau_0, duration)
        self._skipped.owe(-given)
        self._hold = None                   # what the drive held until now is in `late`
        missed = self._skipped.owed
        late = now - start if not given else max(0.0, -missed / tau_0) if tau_0 else 0.0   # [s] at tau_0: its start's
        if late > self.settings.sync_period:
            self.counters["ramps_begun_late"] += 1
            self.ramp_late_max = max(self.ramp_late_max, late)
            self._event(INFO, f"the stance ramp began {late * 1e3:.1f} ms after its touchdown ({why}): "
                              "that part of its impulse given as the current limit allows")

    def _ramp_setting(self, now: float, at_sync: bool = False) -> float:
        """The ramp (2.32) averaged over the SYNC period this setting is held for: the drive holds each
        current until the next RPDO, so the period in which the touchdown falls gets its share of tau_0
        and every period the impulse the ramp gives there (sampled at `now`, the share was lost or
        not by where the touchdown fell between two SYNCs: up to 1 ms of onset, 0.1 cm of apex); plus what
        a late ramp still owes (skipped.py, chosen `at_sync`)."""
        tau_0, duration, start = self._ramp[:3]
        since = float(now - start)
        period = self.settings.sync_period
        self._ramp_part = mean_ramp_torque(since, since + period, float(tau_0), float(duration))
        return self._skipped.setting(self._ramp_part, now if at_sync else None)

    def _rpdo_frame(self, number: int, controlword: int, at_sync: bool = False) -> can.Message:
        if number == 1:
            if self._mode == MODE_RAMP and self._ramp is not None:
                self._ramp_torque = self._ramp_setting(self.clock(), at_sync)
                self._current_ma = self._current_setting(self._ramp_torque)
            setting = self._current_ma if (self._want_enabled and self._mode in (MODE_CURRENT, MODE_RAMP)) else 0
            values = (controlword, OperationMode.CURRENT, setting)
        else:
            values = (controlword, OperationMode.POSITION, self._position_qc)
        return can.Message(arbitration_id=self._rpdo_cob[number], data=RPDO_MAPPINGS[number].encode(values),
                           is_extended_id=False)

    def _send_rpdo(self, now: float, force: bool) -> None:
        controlword = int(self._controlword(now))
        number = 2 if self._mode == MODE_POSITION else 1
        ramp = self._mode == MODE_RAMP and self._ramp is not None
        if ramp:
            self._book_hold(now)
        frame = self._rpdo_frame(number, controlword, at_sync=not force)
        key = (number, bytes(frame.data))
        if not force and (self._sent_since_sync == key or (
                key == self._last_rpdo and now - self._last_rpdo_time < self.settings.rpdo_refresh)):
            return          # this period's RPDO is out already, or the drive has it (applied on reception)
        if self._send(frame):
            self._reset.sent(controlword, self._last_cw, now)
            self._last_cw = controlword
            self._sent_since_sync = key
            self._last_rpdo, self._last_rpdo_time = key, now
            self._hold = (now, self._ramp_part, self._ramp[2]) if ramp and self._want_enabled and self.enabled else None
            if ramp:
                self._sent_torque.add(now, self._ramp_torque if self._want_enabled and self.enabled else 0.0)

    def _book_hold(self, now: float) -> None:
        """Book the ramp's part of a setting chosen at the touchdown and held longer than HOLD_BOOKED periods
        against the ramp (2.32): each setting is the ramp's mean over the period it is meant to be held, but the
        drive holds it until the next RPDO. Under load our own cycle stalls (normal scheduling, 500 Hz: the
        touchdown's first setting, the ramp's share of the period in which it began, held 6 ms, the next apex
        1.4 cm off); what the hold withheld is owed and given as the current limit allows (skipped.py). Only there
        is that much: later a setting differs from the ramp by its slope. And only so long a hold is the driver's
        stall: the simulated robot takes the last setting at each of its steps, so that the shorter holds of a
        command's own RPDO between two SYNCs are no holds to it (booking the owed part of every hold moved the apex
        spread of the in-process 500 Hz graph from 0.042 to 0.047 cm: test_graph_under_load). A hold longer than FROZEN_MIN is no stall (a watchdog
        stop, the robot standing still), and one chosen for a start the ramp has left since (the measured
        touchdown moved it) is the old ramp's: neither is booked."""
        hold = self._hold
        if hold is None:
            return
        sent, ramp_part, chosen_for = hold
        held = now - sent
        tau_0, duration, start = (float(x) for x in self._ramp[:3])
        period = self.settings.sync_period
        self._hold = (now, ramp_part, start)    # booked until now: the drive holds it on until the next RPDO
        if held > FROZEN_MIN or chosen_for != start:
            return
        if held > HOLD_BOOKED * period and sent < start + period:
            self._skipped.owe(ramp_impulse(now - start, tau_0, duration) - ramp_impulse(sent - start, tau_0, duration)
                              - ramp_part * held)

    def _event(self, level: int, text: str, key: str | None = None) -> None:
        """Queue a log line for the caller; with `key`, at most one a second of that kind."""
        if key is not None:
            now = self.clock()
            if now - self._event_times.get(key, -math.inf) < 1.0:
                return
            self._event_times[key] = now
        self.events.append((level, text))
        if len(self.events) > 1000:
            del self.events[:500]

    def drain_events(self) -> list[tuple[int, str]]:
        events, self.events = self.events, []
        return events

