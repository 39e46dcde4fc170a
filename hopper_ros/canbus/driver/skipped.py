"""The impulse a stance ramp was not given, given back as the current limit allows (no ROS).

A ramp whose start had passed when it reached the driver (its command came after the touchdown, or the
measured touchdown came before the predicted one it waited for) misses its first part. On the demo's strides
(tau_0 ~11 N m, the drive's limit 12.5 N m) each ms missed moved the next apex by ~4 mm; given on top of the
ramp as soon as the limit allows, 2 ms late moves it ~1 mm, 3 ms ~2.4 mm (docs/motor_driver.md).
A touchdown's setting the drive held longer than its period (the driver's own cycle stalled: the drive holds
each current until the next RPDO) is booked here too (`owe`). `SentTorque` keeps what the drive was sent for a
ramp, so that what a late start owes is the ramp's impulse less what was given (a ramp whose start the count of
a stand-still had moved ahead of the measured touchdown had its torque on the leg from the touchdown on: owed in
full, it was paid twice at the current limit, the apex 0.75 cm off: bench_demo_load --bag, docs/motor_driver.md).
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
        self._booked_at = -math.inf          # when it was booked (for a period)

    def begin(self, late: float, tau_0: float, duration: float) -> None:
        """A ramp (2.32) of (tau_0, duration) begins `late` [s] after its start (not late: nothing owed)."""
        self.owed = ramp_impulse(late, tau_0, duration) if late > 0.0 else 0.0
        self.extra = 0.0

    def owe(self, impulse: float) -> None:
        """Book `impulse` [N m s] more owed (of the ramp's sign), or given beyond the ramp (the other sign)."""
        self.owed += impulse

    def setting(self, torque: float, sync_at: float | None) -> float:
        """The ramp's `torque` for this SYNC period plus what of the owed impulse the limit leaves room for (less,
        down to none, for impulse given beyond it): chosen and booked at the period's SYNC (`sync_at`, the time:
        its RPDO is held a period), kept by a command's RPDO within it (None). A SYNC sooner than a period after
        the last gives back what that one booked and did not hold (the cycle runs the periods it missed after a
        stall at once: a late ramp's owed impulse was spent by them, 9 mN m s in 0.4 ms in a loaded run). Nothing
        is owed once the ramp is over."""
        if sync_at is not None:
            self.owed += self.extra * max(0.0, self.sync_period - (sync_at - self._booked_at))
            self._booked_at = sync_at
            self.extra = 0.0
            if torque and self.owed:
                room = max(0.0, self.torque_limit - abs(torque)) if self.owed * torque > 0.0 else abs(torque)
                self.extra = math.copysign(min(abs(self.owed) / self.sync_period, room), self.owed)
                self.owed -= self.extra * self.sync_period
            elif not torque:
                self.owed = 0.0
        setting = torque + self.extra
        return setting if setting * torque >= 0.0 else 0.0     # less, down to none: never the other sign


class SentTorque:
    """The settings a ramp was sent, each held by the drive until the next: the impulse given between two instants."""

    KEPT = 512          # settings kept (a ramp is tens of SYNC periods; a held one may run longer)

    def __init__(self) -> None:
        self._sent: list[tuple[float, float]] = []     # (when, hip torque [N m])

    def reset(self) -> None:
        self._sent.clear()

    def add(self, at: float, torque: float) -> None:
        if self._sent and self._sent[-1][1] == torque:
            return                                     # held on: the same setting
        self._sent.append((at, torque))
        if len(self._sent) > self.KEPT:
            del self._sent[:-self.KEPT // 2]

    def held_at(self, instant: float) -> float:
        """[N m] The setting the drive held at `instant` (the last sent before it; none before the first)."""
        held = 0.0
        for at, torque in self._sent:
            if at >= instant:
                break
            held = torque
        return held

    def between(self, begin: float, end: float, unanswered: tuple[float, float] = (0.0, 0.0)) -> float:
        """[N m s] The impulse the settings gave from `begin` to `end`, none in the span `unanswered` (the drive
        answered no SYNC: the simulated robot stood still, and took the last setting of that span when it woke)."""
        given = 0.0
        for index, (at, torque) in enumerate(self._sent):
            until = min(self._sent[index + 1][0] if index + 1 < len(self._sent) else end, end)
            at = max(at, begin)
            overlap = max(0.0, min(until, unanswered[1]) - max(at, unanswered[0]))
            given += torque * (max(0.0, until - at) - overlap)
        return given
