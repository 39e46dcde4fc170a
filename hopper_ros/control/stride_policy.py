"""The deadbeat controller's whole stride policy (Fig 5.3, or the single-stride experiment of
Fig 4.1) as a plain object: apexes, gait events and a drive fault in, the motor command for any
instant out. The deadbeat_controller node wires its topics to it; the in-process graph
(`harness.graph_lockstep`) runs the same object, so the two run one piece of code.

- At an apex: closed loop, the two-stage decision (`closed_loop.decide_at_apex`) for the
  setpoint in force; single stride, the plan for the apex the robot was thrown to (the ramp ends
  at the model's predicted lift-off), BRAKE after the second apex.
- In stance: MODE_RAMP, the ramp (2.32) stamped with the touchdown; the driver computes its
  current every SYNC period itself, so delays and jitter of the command stream neither shift nor
  stretch it.
- With `ramp_ahead` the ramp goes out at the pre-touchdown event already, stamped with the
  touchdown predicted from that event's state (physics.flight.touchdown_time): zero current until
  then; the measured touchdown re-stamps it. No touchdown within `touchdown_grace` of the
  predicted one cancels the ramp (zero current, counted). The grace is the robot's time: while the
  motor driver says the drive stands still (it answers no SYNC: the simulated robot's process
  stopped, `on_drive_silence`) the robot does not fly on, so no ramp is cancelled, and the time it
  stood still moves the deadline (the driver moves the ramp by it too).
- Single stride: `brake_disable_delay` after BRAKE began the drive is disabled (the robot sits back).
- Hopping (past the first apex), no gait event for `sensing_timeout` (longer than any phase lasts):
  the sensing chain stopped or the robot lies still: the drive is disabled until events come again
  (`on_sensing`), no torque from a stale state.
- A command goes out when it changes and otherwise every `keep_alive` (`due`), which feeds the
  motor driver's watchdog.
Times are seconds on one clock (the event stamps' clock); a caller may hand its own stamp of an
instant along (`now_stamp`, the touchdown's `stamp`), which a command at that instant carries back.
The ramp's instants are kept less the stand-stills the stamps have stepped by (`on_clock`), so that a
ramp predicted before the robot stood still goes out where the robot's clock puts it after.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Mapping

from hopper_ros.physics.flight import touchdown_time
from hopper_ros.physics.predictors import predict_stride

from .closed_loop import decide_at_apex
from .deadbeat import DeadbeatController, StrideDecision
from .stride_machine import MODE_DISABLED, Phase, StrideMachine, StridePlan

MODE_RAMP = 3   # MotorCommand.MODE_RAMP: the driver runs the ramp (2.32) from the stamp


@dataclass(frozen=True)
class StrideSettings:
    """control.yaml `stride` (beyond the thesis): the stance ramp's timing and the keep-alive."""

    ramp_ahead: bool = False            # send the ramp at pre-touchdown, stamped with the predicted touchdown
    touchdown_grace: float = 0.02       # [s] no touchdown this long after the predicted one: ramp cancelled
    stand_still_step: float = 0.01      # [s] a step of the sensing clock's mapping this large: the robot stood still
    keep_alive: float = 0.003           # [s] an unchanged command is repeated this often
    executor_timeout: float = 0.02      # [s] the node's executor silent this long: its repeats stop (stale state)
    sensing_timeout: float = 0.5        # [s] no gait event this long while hopping: sensing lost, drive disabled
    keep_alive_priority_boost: int = 10  # SCHED_FIFO priority of the node's repeating thread above its own
    brake_disable_delay: float = 0.5    # [s] single stride: braking this long, then the drive disabled
    fault_acknowledge: float = 0.02     # [s] MODE_DISABLED this long after the last report of a drive fault
    settled_angle: float = 0.05         # [rad] the leg this far from its touchdown angle at pre-touchdown ...
    settled_rate: float = 5.0           # [rad/s] ... or swinging this fast: held until `release_lead` before touchdown
    release_lead: float = 0.003         # [s] an unsettled leg let go this long before its predicted touchdown

    @classmethod
    def from_mapping(cls, section: Mapping[str, Any], **overrides: Any) -> "StrideSettings":
        known = {f.name for f in fields(cls)}
        values = {k: v for k, v in {**dict(section), **overrides}.items() if k in known and v is not None}
        return cls(**values)


@dataclass(frozen=True)
class Command:
    """A motor command (MotorCommand's fields): mode, setpoint, ramp duration and its stamp."""

    mode: int
    setpoint: float
    duration: float = 0.0
    time: float = math.nan      # [s] the stamp: now, the touchdown or the predicted touchdown
    stamp: Any = None           # the caller's own stamp of that instant when it gave one
    clock_offset: float = math.nan   # [s] the sensing clock's mapping the stamp is on (host minus robot
                                     #   time; nan: no event has told it yet)


class StridePolicy:
    """One controller's strides: closed loop (`single=None`) or one stride of (tau_0, touchdown_angle)."""

    def __init__(self, controller: DeadbeatController, settings: StrideSettings = StrideSettings(),
                 single: tuple[float, float] | None = None) -> None:
        self.controller, self.params, self.settings = controller, controller.params, settings
        self.machine = StrideMachine()
        self.single = single
        if single is not None:
            tau_0, angle = single
            if not (math.isfinite(tau_0) and math.isfinite(angle)):
                raise ValueError("a single stride needs a finite tau_0 and touchdown_angle")
            self.machine.start_single_stride(StridePlan(tau_0, angle, math.inf))
        self.setpoint: tuple[float, float] | None = None
        self.last_decision: StrideDecision | None = None
        self.counters = {"strides": 0, "infeasible": 0, "faults": 0, "commands": 0, "touchdowns_missed": 0,
                         "sensing_lost": 0, "releases_held": 0}
        self.events: list[tuple[str, str]] = []     # (logger level, text) for the caller's log
        self._clock_offset = math.nan   # [s] the sensing clock's mapping (host minus robot time) of the last event
        self._stood_still = 0.0         # [s] its steps of a stand-still's size so far (`stand_still_step`)
        # the ramp's instants on the robot's clock: host time less the stand-stills in the stamps so far
        self._touchdown: tuple[float, Any, float] = (math.nan, None, 0.0)   # that time, stamp, _stood_still then
        self._predicted_touchdown = math.nan
        self.prediction_late_max = self.prediction_early_max = 0.0   # [s] predicted touchdowns against measured
        self._stood_still_at_prediction = 0.0
        self._release_at = math.inf     # the pre-touchdown instant heard ahead: the leg let go then
        self._cancelled_ramp = False
        self._brake_since = math.nan
        self._last = (MODE_DISABLED, 0.0)
        self._last_sent = -math.inf
        self._sensed = math.nan         # when the last gait event or apex came (the caller's clock)
        self._drive_silent = False      # the motor driver says the drive (the robot) stands still
        self._frozen_time = 0.0         # [s] the time it stood still so far (the driver's count)
        self._frozen_at_prediction = 0.0
        self._acknowledge = -math.inf   # a drive fault: MODE_DISABLED until then (fault_acknowledge)
        self.sensing_lost = False

    @property
    def phase(self) -> Phase:
        return self.machine.phase

    # ------------------------------------------------------------------ inputs
    def on_setpoint(self, apex_height: float, forward_speed: float) -> None:
        self.setpoint = (apex_height, forward_speed)
        if self.single is None:             # ready for the throw: the leg at the neutral angle
            self.controller.prime(*self.setpoint)
            self.machine.hold(self.controller.neutral_angle(forward_speed))

    def on_apex(self, apex_height: float, forward_speed: float, stride_index: int) -> StrideDecision | None:
        """The decision this apex made (None: none, e.g. no setpoint yet)."""
        self._release_at = math.inf
        if self.single is not None:
            return self._single_stride_apex(apex_height, forward_speed, stride_index)
        self.controller.observe(apex_height, forward_speed)
        if self.setpoint is None:
            return None
        decision = decide_at_apex(self.controller, self.machine, apex_height, forward_speed, self.setpoint,
                                  stride_index)
        self.last_decision = decision
        self.counters["strides"] += 1
        if not decision.feasible:
            self.counters["infeasible"] += 1
            self.events.append(("warning", f"stride {stride_index}: infeasible ({decision.reason}); leg held, no torque"))
        return decision

    def _single_stride_apex(self, apex_height: float, forward_speed: float, stride_index: int) -> StrideDecision | None:
        decision = None
        if self.machine.phase is Phase.INITIALISE:
            tau_0, angle = self.single
            prediction = predict_stride(self.params, apex_height, forward_speed, angle, tau_0)
            ramp = prediction.ramp_duration if prediction.ok else 0.0
            self.machine.plan = StridePlan(tau_0, angle, ramp)
            decision = StrideDecision(stride_index, bool(prediction.ok), prediction.failure, tau_0, angle, ramp,
                                      prediction.next_apex_height, prediction.next_forward_speed,
                                      prediction.stride_time, math.nan, math.nan)
        self.machine.on_apex(None)
        if self.machine.phase is Phase.BRAKE:
            self.events.append(("info", "single stride done: braking"))
        return decision

    def on_pre_touchdown(self, time: float, z: float, z_dot: float, leg_angle: float, leg_angle_rate: float) -> None:
        """Pre-touchdown at `time`, the body's state there (for the predicted touchdown). The event
        comes ahead of its time (sensing.yaml `pre_touchdown_lead`): the leg is let go at `time`, by
        whichever command is asked for first from then on (the node's repeats run on time, whatever
        its executor does), and the ramp is scheduled from then at the predicted touchdown. So an
        event that reaches the controller late by less than the lead costs nothing (acted on when
        heard, 1 ms ahead, it sent the ramp late under a real-time load beside the loop: its torque
        reached the leg 5.4 ms after a touchdown).

        A leg still swinging to its touchdown angle there (off by over `settled_angle` or faster than
        `settled_rate`: the swing began late, after a drive fault or a low apex's short flight) is held
        in position until `release_lead` before the touchdown at that angle (the ramp predicted at it too).
        Let go mid-swing, it swung on past its angle by 0.4 rad and the robot fell (a soak: two drive
        faults in one flight)."""
        self._release_at = time
        self._predicted_touchdown = time - self._stood_still + self.time_to_touchdown(
            z, z_dot, leg_angle, leg_angle_rate) if self.settings.ramp_ahead else math.nan
        plan, s = self.machine.plan, self.settings
        if plan is not None and (abs(leg_angle - plan.touchdown_angle) > s.settled_angle
                                 or abs(leg_angle_rate) > s.settled_rate):
            held_flight = self.time_to_touchdown(z, z_dot, plan.touchdown_angle, 0.0)   # the leg held at its angle
            self._release_at = time + max(0.0, held_flight - s.release_lead)
            if s.ramp_ahead:
                self._predicted_touchdown = time - self._stood_still + held_flight
            self.counters["releases_held"] += 1
            self.events.append(("warning", f"pre-touchdown with the leg {leg_angle - plan.touchdown_angle:+.3f} rad "
                                           f"off its angle at {leg_angle_rate:+.1f} rad/s: held until "
                                           f"{(self._release_at - time) * 1e3:.0f} ms later"))
        self._frozen_at_prediction, self._stood_still_at_prediction = self._frozen_time, self._stood_still
        self._cancelled_ramp = False

    def time_to_touchdown(self, z: float, z_dot: float, leg_angle: float, leg_angle_rate: float) -> float:
        """The flight (2.14) from this state until the toe meets the ground."""
        p = self.params
        return touchdown_time(z, z_dot, leg_angle, leg_angle_rate, p.rest_length, p.gravity, p.flight_damping_vertical)

    def on_touchdown(self, time: float, stamp: Any = None) -> None:
        self._release_at = math.inf
        self.machine.on_touchdown(time)
        self._touchdown = (time - self._stood_still, stamp, self._stood_still)
        if math.isfinite(self._predicted_touchdown):     # on the robot's clock, both
            late = self._predicted_touchdown - self._touchdown[0]
            self.prediction_late_max = max(self.prediction_late_max, late)
            self.prediction_early_max = max(self.prediction_early_max, -late)

    def on_clock(self, clock_offset: float) -> None:
        """The sensing clock's mapping of the gait event that comes next (its state's stamp minus its
        robot time). The ramp's instants are kept on the robot's clock and each command maps them with
        the latest mapping: after the robot stood still the stamps re-anchor by that time, and a ramp
        predicted before it follows (the driver, told by the step of `Command.clock_offset`, then moves
        no ramp by its own count of the stand-still, 1-4 SYNCs off; nor a touchdown measured after it,
        which it could not tell from one stamped on the old mapping). Only steps of a stand-still's size
        count (`stand_still_step`): a re-anchor of a few ms under load would move a running ramp, repeating
        or skipping a part of it."""
        if not math.isfinite(clock_offset):
            return
        step = clock_offset - self._clock_offset
        if abs(step) >= self.settings.stand_still_step:       # False while unknown (nan)
            self._stood_still += step
        self._clock_offset = clock_offset

    def on_liftoff(self, leg_angle: float) -> None:
        self.machine.on_liftoff(leg_angle)

    def on_sensing(self, now: float) -> None:
        """A gait event or an apex came at `now` (the clock of `command`): the sensing chain is alive."""
        self._sensed = now
        if self.sensing_lost:
            self.sensing_lost = False
            self.events.append(("info", "gait events again: the drive follows the strides once more"))

    def on_drive_silence(self, silent: bool, frozen_time: float) -> None:
        """The motor driver's word on the drive: `silent` while it answers no SYNC (the robot stands
        still), `frozen_time` [s] the time it stood still so far."""
        self._drive_silent = bool(silent)
        if not math.isfinite(frozen_time):
            return
        if frozen_time < self._frozen_time:      # a new motor driver (respawned) counts from 0
            self._frozen_at_prediction = min(self._frozen_at_prediction, frozen_time)
        self._frozen_time = frozen_time

    def on_drive_fault(self, message: str) -> bool:
        """The motor driver reports a drive fault or a lost drive: no torque, and the stream
        acknowledges it (MODE_DISABLED until `fault_acknowledge` after the last report, the driver's
        cue to reset a fault). False for a report of a fault already acknowledged.

        While hopping the stride is SAFE (no torque in stance, the leg held in flight) until the
        drive is back; the stride goes on if it has not lifted off yet (`StrideMachine.resume`),
        else at the next apex. A fault is acknowledged in any phase: one acknowledged only by a
        sensing chain silent for `sensing_timeout` left a drive that faulted once (its heartbeat
        consumer, the driver starved 15 ms) faulted, and the robot fell after every throw (63 times in
        a soak); one held SAFE with the leg held in position through the stance (a large hip torque)
        threw the robot backwards, and it fell in the next stride. Before the first apex (the robot
        held for its throw) nothing latches: a start-up that failed once (the simulated robot's hub
        not up yet) left the demo waiting for an enabled drive forever."""
        self._acknowledge = math.inf            # MODE_DISABLED from the next command on
        if self.machine.faulted:
            return False
        self.counters["faults"] += 1
        if self.machine.phase in (Phase.IDLE, Phase.INITIALISE):
            self.events.append(("error", f"motor driver: {message} (no stride yet: acknowledged, the leg is held "
                                         "once the drive is back)"))
            return True
        self.machine.fault(f"motor driver: {message}")
        self.controller.forget_stride()
        self.events.append(("error", self.machine.reason + " (acknowledged: the stride goes on once the drive "
                                                           "is back)"))
        return True

    # ------------------------------------------------------------------ output
    def command(self, now: float, now_stamp: Any = None) -> Command:
        """The motor command for the instant `now`."""
        machine, s = self.machine, self.settings
        if now >= self._release_at:
            self._release_at = math.inf
            machine.on_pre_touchdown()
        if (machine.phase not in (Phase.IDLE, Phase.INITIALISE, Phase.BRAKE) and now - self._sensed > s.sensing_timeout
                and not self.sensing_lost):
            # hopping, and no event for longer than any phase lasts: the sensing chain stopped (a node died)
            # or the robot lies still. No torque from a stale state: the drive off until events come again
            self.sensing_lost = True
            self.counters["sensing_lost"] += 1
            self.events.append(("error", f"no gait event for {s.sensing_timeout * 1e3:.0f} ms while hopping: "
                                         "sensing lost, drive disabled"))
        offset, stood_still = self._clock_offset, self._stood_still
        if self.sensing_lost:
            return Command(MODE_DISABLED, 0.0, 0.0, now, now_stamp, offset)
        if self._acknowledge == math.inf:
            self._acknowledge = now + s.fault_acknowledge
        if now < self._acknowledge:
            return Command(MODE_DISABLED, 0.0, 0.0, now, now_stamp, offset)
        if machine.faulted:
            resumed = machine.resume()
            self.events.append(("info", "drive fault acknowledged: " + (
                "the stride goes on" if resumed else "no torque until the next apex")))
        mode, setpoint = machine.command(now)
        if machine.phase is Phase.BRAKE:
            if math.isnan(self._brake_since):
                self._brake_since = now
            elif now - self._brake_since > s.brake_disable_delay:
                mode, setpoint = MODE_DISABLED, 0.0     # the robot sits back: drive off
        phase, plan = machine.phase, machine.plan
        if phase is Phase.STANCE and plan is not None:
            # the driver runs the ramp itself, from the touchdown time: jitter in the stream cannot shift it
            touchdown, stamp, stood_still_then = self._touchdown
            return Command(MODE_RAMP, float(plan.tau_0), plan.ramp_duration, touchdown + stood_still,
                           stamp if stood_still_then == stood_still else None, offset)
        if phase is Phase.PRE_TOUCHDOWN and plan is not None and math.isfinite(self._predicted_touchdown):
            # the stand-still since the prediction: in the stamps once they re-anchored, else the driver's count
            frozen = max(0.0, self._frozen_time - self._frozen_at_prediction
                         - (stood_still - self._stood_still_at_prediction))
            deadline = self._predicted_touchdown + stood_still + s.touchdown_grace + frozen
            if now <= deadline or self._drive_silent:
                # scheduled ahead: zero current until the predicted touchdown, then the ramp
                return Command(MODE_RAMP, float(plan.tau_0), plan.ramp_duration, self._predicted_touchdown + stood_still,
                               None, offset)
            if not self._cancelled_ramp:
                self._cancelled_ramp = True
                self.counters["touchdowns_missed"] += 1
                self.events.append(("warning", f"no touchdown within {s.touchdown_grace * 1e3:.0f} ms of the "
                                               f"predicted one: stance ramp cancelled"))
        return Command(mode, float(setpoint), 0.0, now, now_stamp, offset)

    def due(self, command: Command, now: float) -> bool:
        """Whether `command` goes out now: it changed, or `keep_alive` passed (half of it, so a
        timer of that period never skips one). Counted when True."""
        if (command.mode, command.setpoint) == self._last and now - self._last_sent < 0.5 * self.settings.keep_alive:
            return False
        self._last, self._last_sent = (command.mode, command.setpoint), now
        self.counters["commands"] += 1
        return True

    def drain_events(self) -> list[tuple[str, str]]:
        events, self.events = self.events, []
        return events
