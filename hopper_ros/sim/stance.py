"""The stance ramp as the robot felt it, from the simulated robot's true motion (no ROS).

`StanceTorque.add(sample, current_mode)` per period: for each stance (touchdown to lift-off or fall)
the time from the true touchdown to the first period in which the drive was in current mode (the
ramp; in position mode it is the leg held) and the applied hip torque exceeded `threshold` (the
ramp's onset). A stance without any is a ramp cancelled (or never sent); one whose onset came more than
`late_after` after the touchdown a ramp held (stamped ahead of the touchdown, or sent late). A ramp
begun before the touchdown shows as current-mode torque in the flight's last periods (the release gives
none): `early`, how long before the touchdown it reached the leg. The controller and the driver only see
their own side of it; this is what reached the leg.
"""

from __future__ import annotations

import math

THRESHOLD = 0.5      # [N m] applied hip torque that counts as the ramp (the demo's tau_0: 8-12 N m)
LATE_AFTER = 0.005   # [s] an onset later than this after the touchdown: the ramp was held
SAID_AFTER = 0.002   # [s] an onset later than this is said in the log, with how far behind the robot ran
KEEP_ONSETS = 1000   # onsets kept (the counters count them all)


class StanceTorque:
    def __init__(self, threshold: float = THRESHOLD, late_after: float = LATE_AFTER) -> None:
        self.threshold, self.late_after = threshold, late_after
        self.stances = 0
        self.without_torque = 0        # stances in which no torque reached the leg: ramps cancelled
        self.late = 0                  # stances whose torque began more than late_after in: ramps held
        self.onset_max = 0.0           # [s] the latest onset of a stance with torque
        self.onsets: list[float] = []  # [s] per stance (the last KEEP_ONSETS), NaN without torque
        self.early_max = 0.0           # [s] the most a ramp's torque reached the leg before its touchdown
        self.early = 0.0               # [s] the same, of the latest stance
        self._flight_torque_since = math.nan   # [s] current-mode torque in the flight without a break since
        self._touchdown = math.nan
        self._onset = math.nan
        self.behind = 0.0              # [s] the most the robot ran behind its clock from the touchdown to the onset

    def add(self, sample, current_mode: bool = True, behind: float = 0.0) -> None:
        """One period of the simulated robot (sim.robot.SimSample): its events and applied torque;
        `current_mode`: the drive was in current mode (SimRobot.current_mode); `behind`: how far behind
        its clock the period ran (sim/runner.py; kept for each stance from the touchdown to the onset)."""
        torque = current_mode and abs(sample.truth.hip_torque) > self.threshold
        for event in sample.events:
            if event.kind == "touchdown":
                self._touchdown, self._onset, self.behind = event.t, math.nan, 0.0
                since = self._flight_torque_since
                self.early = event.t - since if math.isfinite(since) else 0.0
                self.early_max = max(self.early_max, self.early)
            elif event.kind in ("liftoff", "fall") and math.isfinite(self._touchdown):
                self._close()
        if math.isfinite(self._touchdown) and math.isnan(self._onset):
            self.behind = max(self.behind, behind)
        if math.isfinite(self._touchdown):
            self._flight_torque_since = math.nan
            if torque and math.isnan(self._onset):
                self._onset = sample.truth.t - self._touchdown
        elif not torque:
            self._flight_torque_since = math.nan
        elif math.isnan(self._flight_torque_since):
            self._flight_torque_since = sample.truth.t    # the period ending here: to within a period

    def _close(self) -> None:
        self.stances += 1
        self.onsets.append(self._onset)
        if len(self.onsets) > KEEP_ONSETS:     # a node runs for hours: the last ones
            del self.onsets[:-KEEP_ONSETS // 2]
        if math.isnan(self._onset):
            self.without_torque += 1
        else:
            self.onset_max = max(self.onset_max, self._onset)
            self.late += self._onset > self.late_after
        self._touchdown = math.nan

    def counters(self) -> dict[str, int]:
        return {"stances": self.stances, "stances_without_torque": self.without_torque, "stances_torque_late": self.late}
