"""The hip's state machines: the closed-loop run of Fig 5.3 and the single-stride experiment of
Fig 4.1, as plain objects that turn gait events and ticks into motor commands.

Both share the phases of section 4.1:
- POSITIONING: after an apex, the leg is moved to theta_td and held (drive position mode);
- PRE_TOUCHDOWN: 2 cm above touchdown the position regulator is switched off ("to avoid any
  jump backs just before colliding with the ground"): zero current;
- STANCE: from touchdown the ramp -tau_0 (1 - t/t_f) (2.32), zero after t_f (current mode);
- ASCENT: after lift-off the leg is held at its lift-off angle (position mode).
SAFE (an infeasible stride, a drive fault) puts no torque on the stance: the leg is held in flight
only (a leg held in position through a stance is a large hip torque: it threw the robot backwards
after a fault), and from lift-off at its lift-off angle. A fault's stride goes on (`resume`) when
the drive is back before its lift-off.
The closed loop goes back to POSITIONING at each apex with a new decision (Fig 5.3); the
single-stride experiment holds theta_td while waiting for the throw (INITIALISE) and ends in
BRAKE after the second apex (leg held, then the drive disabled).

Commands are (mode, setpoint) with MotorCommand's modes: 0 disabled, 1 current (hip torque
[N m]), 2 position (leg angle [rad]). `command(now)` gives the command for time `now` [s] (the
robot's clock: event times are in it); the controller node sends it on every event and repeats
it every few milliseconds to feed the motor driver's watchdog.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from hopper_ros.physics.laws import ramp_torque

MODE_DISABLED, MODE_CURRENT, MODE_POSITION = 0, 1, 2


class Phase(Enum):
    IDLE = "idle"                   # nothing commanded yet (no setpoint or no apex)
    INITIALISE = "initialise"       # leg held (single stride: at theta_td), waiting for the first apex
    POSITIONING = "positioning"
    PRE_TOUCHDOWN = "pre-touchdown"
    STANCE = "stance"
    ASCENT = "ascent"
    BRAKE = "brake"                 # single stride: done
    SAFE = "safe"                   # infeasible stride or fault: leg held, no torque


@dataclass(frozen=True)
class StridePlan:
    """The inputs of one stride."""

    tau_0: float             # [N m]
    touchdown_angle: float   # [rad]
    ramp_duration: float     # [s]


class StrideMachine:
    """Fig 5.3 (closed loop, `single_stride=False`) or Fig 4.1 (`single_stride=True`)."""

    def __init__(self, single_stride: bool = False) -> None:
        self.single_stride = single_stride
        self.phase = Phase.IDLE
        self.plan: StridePlan | None = None
        self.hold_angle = math.nan
        self.touchdown_time = math.nan
        self.apexes = 0
        self.reason = ""
        self.in_stance = False              # the gait events' word, whatever the phase (SAFE follows it)
        self.faulted = False                # SAFE for a drive fault (until `resume` or the next apex)
        self._faulted_in: Phase | None = None   # the phase a fault interrupted before lift-off (resume: back to it)

    # ------------------------------------------------------------------ inputs
    def hold(self, angle: float) -> None:
        """Before the first apex of a closed-loop run: hold the leg (the robot is about to be thrown)."""
        if self.phase in (Phase.IDLE, Phase.INITIALISE) and not self.single_stride:
            self.hold_angle = angle
            self.phase = Phase.INITIALISE

    def start_single_stride(self, plan: StridePlan) -> None:
        """Fig 4.1's first phase: hold theta_td and wait for the robot to be thrown to an apex."""
        self.single_stride = True
        self.plan = plan
        self.hold_angle = plan.touchdown_angle
        self.apexes = 0
        self.phase = Phase.INITIALISE

    def on_apex(self, plan: StridePlan | None, reason: str = "") -> None:
        """An apex: the closed loop takes the new plan (None: infeasible -> SAFE, leg held)."""
        self.apexes += 1
        self.in_stance, self.faulted, self._faulted_in = False, False, None
        if self.single_stride:
            if self.phase is Phase.INITIALISE:
                self.phase = Phase.POSITIONING
            elif self.phase in (Phase.ASCENT, Phase.STANCE, Phase.PRE_TOUCHDOWN, Phase.POSITIONING):
                self.phase = Phase.BRAKE
            return
        if plan is None:
            self.phase, self.reason = Phase.SAFE, reason
            return
        self.plan, self.reason = plan, reason
        self.hold_angle = plan.touchdown_angle
        self.phase = Phase.POSITIONING

    def revise(self, plan: StridePlan) -> None:
        """A better plan for the same stride (the controller's stage 2), taken before touchdown."""
        if self.phase in (Phase.POSITIONING, Phase.PRE_TOUCHDOWN, Phase.SAFE) and not self.single_stride \
                and not self.in_stance:
            self.plan, self.hold_angle = plan, plan.touchdown_angle
            if not self.faulted:                 # (a fault's SAFE waits for the drive: `resume`)
                self.reason = ""
                if self.phase is Phase.SAFE:     # infeasible at stage 1, feasible now
                    self.phase = Phase.POSITIONING

    def on_pre_touchdown(self) -> None:
        if self.phase is Phase.POSITIONING:
            self.phase = Phase.PRE_TOUCHDOWN
        elif self._faulted_in is Phase.POSITIONING:
            self._faulted_in = Phase.PRE_TOUCHDOWN

    def on_touchdown(self, time: float) -> None:
        self.in_stance = True
        if self.phase in (Phase.POSITIONING, Phase.PRE_TOUCHDOWN) or self._faulted_in in (
                Phase.POSITIONING, Phase.PRE_TOUCHDOWN):
            self.touchdown_time = time
            if self.phase is Phase.SAFE:
                self._faulted_in = Phase.STANCE
            else:
                self.phase = Phase.STANCE

    def on_liftoff(self, leg_angle: float) -> None:
        self.in_stance = False
        if self.phase in (Phase.STANCE, Phase.SAFE):
            self.hold_angle = leg_angle
        if self.phase is Phase.STANCE:
            self.phase = Phase.ASCENT
        self._faulted_in = None             # a fault's stride is over: SAFE holds the lift-off angle

    def fault(self, reason: str) -> None:
        """A drive fault: SAFE until `resume` (the drive back) or the next apex."""
        if self.phase in (Phase.POSITIONING, Phase.PRE_TOUCHDOWN, Phase.STANCE) and self.plan is not None:
            self._faulted_in = self.phase
        self.phase, self.reason, self.faulted = Phase.SAFE, reason, True

    def resume(self) -> bool:
        """The drive is back after a fault: the stride it interrupted goes on if it has not lifted
        off yet (the leg positioned again before the touchdown; in the stance, the ramp from the
        touchdown, which the motor driver starts at most its `max_ramp_age` back: the stride's impulse
        late rather than lost, a stance without it cost 1.2 m/s and the robot fell). True if it did."""
        if not self.faulted:
            return False
        self.faulted = False
        if self._faulted_in is None:
            return False
        self.phase, self._faulted_in, self.reason = self._faulted_in, None, ""
        if self.phase is not Phase.STANCE:
            self.hold_angle = self.plan.touchdown_angle
        return True

    # ------------------------------------------------------------------ output
    def command(self, now: float) -> tuple[int, float]:
        """(mode, setpoint) for time `now` [s]."""
        phase = self.phase
        if phase is Phase.IDLE:
            return MODE_DISABLED, 0.0
        if phase is Phase.STANCE:
            return MODE_CURRENT, ramp_torque(float(now - self.touchdown_time), float(self.plan.tau_0),
                                             float(self.plan.ramp_duration))       # (2.32)
        if phase is Phase.PRE_TOUCHDOWN or (phase is Phase.SAFE and self.in_stance):
            return MODE_CURRENT, 0.0
        if math.isfinite(self.hold_angle):
            return MODE_POSITION, self.hold_angle
        return MODE_DISABLED, 0.0
