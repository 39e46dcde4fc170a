"""The impulse a late stance ramp skipped, given back as the current limit allows (no ROS).

A ramp whose start had passed when it reached the driver (its command came after the touchdown, or the
measured touchdown came before the predicted one it waited for) misses its first part. On the demo's strides
(tau_0 ~11 N m, the drive's limit 12.5 N m) each ms missed moved the next apex by ~4 mm; given on top of the
ramp as soon as the limit allows, 2 ms late moves it ~1 mm, 3 ms ~2.4 mm (docs/motor_driver.md).
"""

from __future__ import annotations

import math

from hopper_ros.physics.laws import ramp_impulse


class SkippedImpulse:
    def __init__(self, torque_limit: float, sync_period: float) -> None:
        self.torque_limit = torque_limit     # [N m] the hip torque at the drive's current limit
        self.sync_period = sync_period
        self.owed = 0.0                      # [N m s] still to give
        self.extra = 0.0                     # [N m] the part of this SYNC period's setting that gives it

    def begin(self, late: float, tau_0: float, duration: float) -> None:
        """A ramp (2.32) of (tau_0, duration) begins `late` [s] after its start (not late: nothing owed)."""
        self.owed = ramp_impulse(late, tau_0, duration) if late > 0.0 else 0.0
        self.extra = 0.0

    def setting(self, torque: float, at_sync: bool) -> float:
        """The ramp's `torque` for this SYNC period plus what of the owed impulse the limit leaves room for:
        chosen and booked `at_sync` (the period's RPDO, held a whole period), kept by a command's RPDO within it."""
        if at_sync:
            self.extra = 0.0
            if self.owed * torque > 0.0:     # owed, and of the ramp's sign (given already once it flips)
                room = max(0.0, self.torque_limit - abs(torque))
                self.extra = math.copysign(min(abs(self.owed) / self.sync_period, room), self.owed)
                self.owed -= self.extra * self.sync_period
            else:
                self.owed = 0.0
        return torque + self.extra
