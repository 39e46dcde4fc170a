"""When the drive, and the robot with it, stood still: told from its answers to SYNC (no ROS).

A drive answers every SYNC with its TPDOs (transmission type 1). The simulated robot's drive stops
answering when its process stops (sim/runner.py); past RESYNC_AFTER (20 ms) its world stands still
for the stall and it answers none of the SYNCs of that time, while a shorter stall is caught up and
every SYNC answered late. Answers merely late (a loaded host, the hub's transit) look the same until
they come. So:

- `silent`: no answer for SILENT_PERIODS SYNC periods; the robot may be standing still;
- `standing_still(now)` [s]: the present silence once it is longer than FROZEN_AFTER, which no caught-up
  stall and no transit delay reaches: the robot stands still, from its last answer on;
- when the answers are back and have settled (SETTLE), the SYNCs left unanswered for good are the time
  the robot stood still (`update` returns it; fewer than FROZEN_MIN's worth are answers still in
  transit); `frozen_time` adds them up and `frozen_after(stamp)` maps an instant of the robot's onto
  the host clock.
- `reflect()`: the sensing clock has re-anchored by the latest stand-still (the commands' stamps are on
  the robot's clock as it now stands): no time counted so far moves a stamp any more (`frozen_time` still
  adds it up). The answers tell a stand-still to within 1-4 SYNCs (a stopped process's hub sends the
  answers it held first); the re-anchored stamps carry it to within the sensing clock's bound.
"""

from __future__ import annotations

import math
from collections import deque

SILENT_PERIODS = 3      # no answer for this many SYNC periods: silent (the robot may stand still)
FROZEN_AFTER = 0.025    # [s] silent this long: the robot stands still (past sim/runner.py RESYNC_AFTER, 20 ms,
                        #   plus the frames' transit)
FROZEN_MIN = 0.01       # [s] fewer SYNCs than this left unanswered are answers still in transit
SETTLE = 0.005          # [s] after a silence, the late answers still coming in this long
SILENCES_KEPT = 8       # the last times the robot stood still, kept for `frozen_after`
STOOD_STILL_LATELY = 0.25   # [s] a stand-still that ended this recently may still come as a re-anchored sensing
                            #   clock (it re-anchors clock_reanchor_after, 10 ms, after the robot is back)
STAMP_SHIFT_KEPT = 0.5      # [s] a re-anchor taken for the host's (MotorDriver._note_clock) not taken back by a
                            #   step earlier within this long was the robot's after all: the stamps are followed


class DriveStillness:
    def __init__(self, sync_period: float, now: float) -> None:
        self.sync_period = sync_period
        self.frozen_time = 0.0                    # [s] the robot stood still so far
        self.sent = self.answered = 0             # SYNCs sent, SYNCs answered (their first TPDO)
        self._last_answer = now
        self._silence_began: float | None = None  # the last answer before the present silence
        self._settling_until = -math.inf          # a silence ended: its late answers still coming
        self._least_unanswered: int | None = None  # while settling
        self._floor: int | None = None            # SYNCs known never to be answered (start-up, standing still)
                                                  #   and the fewest in transit over the last SETTLE (the same
                                                  #   window as the one a silence's count is taken over)
        self._recent: deque[tuple[float, int]] = deque()   # (when, SYNCs unanswered) over the last SETTLE
        self._silences: list[tuple[float, float]] = []   # (when it ended, how long it stood still)
        self._ended = now                         # the first answer after the last silence
        self.silence_span = (-math.inf, -math.inf)   # [s] (the answer before, the one after) the last silence
        self.reflected = False                    # the latest stand-still is in the sensing clock's stamps
        self._last_stood_still = -math.inf        # when the latest stand-still ended (reflected or not)
        self._answering_since: float | None = None   # the first answer of the present run of answers
        self._last_update = now                   # the last SYNC period (our own cycle: it may stall too)

    @property
    def silent(self) -> bool:
        return self._silence_began is not None

    @property
    def settling(self) -> bool:
        """A silence ended and its late answers may still be coming: its count is not known yet."""
        return self._least_unanswered is not None

    def on_answer(self, now: float) -> None:
        self.answered += 1
        self._last_answer = now
        if self._answering_since is None:
            self._answering_since = now

    def standing_still(self, now: float) -> float:
        """[s] The present silence, once it is long enough to be the robot standing still (and is not yet
        in the sensing clock's stamps)."""
        if self._silence_began is not None and not self.reflected and now - self._silence_began > FROZEN_AFTER:
            return now - self._silence_began
        return 0.0

    def pending(self, now: float, stamp: float = -math.inf) -> float:
        """[s] The latest stand-still not yet settled, if it ended after `stamp`: the present silence's
        (`standing_still`), or that of a silence whose answers are still coming in (as far as they
        tell so far)."""
        if self._least_unanswered is not None and stamp < self._ended and not self.reflected:
            frozen = max(0, self._least_unanswered - self._floor) * self.sync_period
            return frozen if frozen >= FROZEN_MIN else 0.0
        return self.standing_still(now)

    def covers(self, stamp: float) -> bool:
        """Whether the latest stand-still, not yet settled, came after the instant `stamp` (so that a
        ramp from that stamp moves by it)."""
        return not self.reflected and (self.silent or (self._least_unanswered is not None and stamp < self._ended))

    def frozen_after(self, stamp: float, now: float) -> float:
        """[s] How long the robot stood still after the instant `stamp` (times that ended after it, and
        the latest one), which its host time must move by. A time is counted whole even when the
        stamp falls inside it: no instant of the robot's lies there, so such a stamp was mapped from
        the robot's clock as it stood before (the sensing clock re-anchors only after it) and lies
        that whole time early."""
        return sum(frozen for ended, frozen in self._silences if ended > stamp) + self.pending(now, stamp)

    def unanswered_span(self, now: float) -> tuple[float, float]:
        """[s] From the answer before the present silence (or the last one) to the answer after it (now while it
        lasts): when what the drive was sent may not have reached a robot that ran."""
        if self._silence_began is not None:
            return self._silence_began, now
        return self.silence_span

    def stood_still_lately(self, now: float) -> bool:
        """Whether the robot may have stood still lately: its drive not answering every SYNC for the last
        STOOD_STILL_LATELY (starting, silent now, a silence's count still settling, our own cycle stalled within
        it: its SYNCs were not sent, so the robot could stand still unanswered), or a stand-still ended within
        it. A sensing clock re-anchored by a stand-still's worth while the drive answered every SYNC is the host
        reading the robot's packets late (a starved process catching up at less than twice their pace), not the
        robot standing still."""
        answering = (self._answering_since is not None and now - self._answering_since >= STOOD_STILL_LATELY
                     and now - self._last_update < FROZEN_MIN)      # (our cycle stalled until now: it has not run yet)
        return not answering or self.silent or self.settling or now - self._last_stood_still < STOOD_STILL_LATELY

    def reflect(self) -> None:
        """The sensing clock re-anchored by the latest stand-still (`reflected`, until the next silence):
        the stamps are on the robot's clock as it now stands, so no stand-still so far moves them."""
        self.reflected = True
        self._silences = []

    def update(self, now: float) -> float | None:
        """Once a SYNC period, before its SYNC: the time [s] the robot stood still in a silence whose
        answers have just settled (0.0 when it ran on), else None."""
        unanswered = self.sent - self.answered
        if now - self._last_update >= FROZEN_MIN:
            # our own cycle stalled (a starved host): no SYNC went out meanwhile, so a stand-still of the
            # robot then left no SYNC unanswered; the answers since are no run that watched for one
            self._answering_since = None
        self._last_update = now
        if self._floor is None:
            if not self.answered:               # not answering yet (starting): nothing to tell
                return None
            self._floor = unanswered
        quiet = now - self._last_answer > SILENT_PERIODS * self.sync_period
        if quiet:
            self._answering_since = None
        if quiet and self._silence_began is None:
            self._recent.clear()                    # the floor stays the one just before the silence
            result = self._settle() if self._least_unanswered is not None else None
            self._silence_began, self.reflected = self._last_answer, False
            return result
        if quiet:
            return None
        if self._silence_began is not None:           # answers again: their backlog may still be coming
            self.silence_span = (self._silence_began, self._last_answer)
            self._silence_began, self._settling_until = None, now + SETTLE
            self._least_unanswered = unanswered
            self._ended = self._last_answer
            return None
        if self._least_unanswered is None:
            self._recent.append((now, unanswered))
            while self._recent[0][0] < now - SETTLE:
                self._recent.popleft()
            self._floor = min(u for _, u in self._recent)
            return None
        self._least_unanswered = min(self._least_unanswered, unanswered)
        return self._settle() if now >= self._settling_until else None

    def _settle(self) -> float:
        excess = max(0, self._least_unanswered - self._floor)
        self._least_unanswered = None
        frozen = excess * self.sync_period
        if frozen < FROZEN_MIN:
            return 0.0
        self._floor += excess
        self.frozen_time += frozen
        self._last_stood_still = self._ended
        if self.reflected:          # in the stamps already: it moves nothing
            return 0.0
        self._silences = [*self._silences[1 - SILENCES_KEPT:], (self._ended, frozen)]
        return frozen
