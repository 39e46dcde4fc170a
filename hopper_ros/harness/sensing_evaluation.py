"""Ground truth for the sensing stages from the simulated robot, and scoring against it (no ROS).

`record_experiments` runs section 4.1's single-stride experiments on `SimRobot` (thrown anew
after each, `sim.experiment.ExperimentSeries`) and keeps every packet, true state and true event.
`true_events` turns them into the events the detector must find, on the simulation clock:

- apex, touchdown, bottom, lift-off: the plant's own events (located to 1e-10 s);
- pre-touchdown: where the toe height z - rho_0 cos(theta) last falls through
  `pre_touchdown_height` before a touchdown, interpolated between the 1 kHz true states;
- required are the events of clean strides (apex to apex: touchdown, bottom, lift-off, apex,
  with a real flight after the lift-off); the events of other strides (a fall, the toe scuffing
  the ground, a touch of no duration, a hop too small to time; the thesis discards such
  experiments, 12 of 132) are optional: a detection may match them, none is demanded. A
  pre-touchdown at an apex whose toe is already below the pre-touchdown height is optional too
  (the simulator throws the robot again right after the apex that ends an experiment).

`match_events` pairs detected with true events of the same kind, nearest in time within a window;
a detection matching no true event is `extra` inside a clean stride and `unconfirmed` elsewhere
(in a stride the simulator ends in a fall or in a sticky contact its events cannot describe).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

from hopper_ros.hardware import packet as packet_format
from hopper_ros.hardware.packet import EncoderPacket
from hopper_ros.sim.experiment import ExperimentSeries
from hopper_ros.sim.robot import MCU_CLOCK_START_US, SimRobot, TrueState

from hopper_ros.sensing.samples import EventType

MCU_CLOCK_OFFSET = MCU_CLOCK_START_US * 1e-6   # [s] microcontroller time at simulation time 0
KINDS = {"apex": EventType.APEX, "touchdown": EventType.TOUCHDOWN, "bottom": EventType.BOTTOM,
         "liftoff": EventType.LIFTOFF}


@dataclass(frozen=True)
class TrueEvent:
    kind: EventType
    time: float              # [s] simulation time
    optional: bool = False


@dataclass
class Recording:
    packets: list[EncoderPacket] = field(default_factory=list)
    truth: list[TrueState] = field(default_factory=list)
    plant_events: list = field(default_factory=list)    # PlantEvent, incl. "fall"
    throws: list[float] = field(default_factory=list)   # [s] simulation times of the throws


def record_experiments(robot: SimRobot, duration: float, seed: int = 0) -> Recording:
    """Run single-stride experiments for `duration` simulated seconds, each thrown after the last."""
    series = ExperimentSeries(robot, seed=seed)
    recording = Recording()
    end = robot.t + duration
    while robot.t < end - 1e-9:
        if robot.experiment is None or robot.experiment.done:
            series.start_next()
            recording.throws.append(robot.t)
        sample = robot.step()
        recording.packets.append(sample.packet)
        recording.truth.append(sample.truth)
        recording.plant_events.extend(sample.events)
    return recording


def toe_heights(truth: Iterable[TrueState], rest_length: float) -> list[tuple[float, float]]:
    """(t, z - rho_0 cos(theta)) of every true state."""
    return [(state.t, state.z - rest_length * math.cos(state.leg_angle)) for state in truth]


@dataclass
class Truth:
    events: list[TrueEvent]                    # sorted by time
    clean_spans: list[tuple[float, float]]     # (start, end) [s] of the clean strides


def true_events(plant_events: Iterable, toe_height_samples: list[tuple[float, float]], rest_length: float,
                pre_touchdown_height: float, min_ascent: float = 0.015,
                min_apex_clearance: float = 0.005, boundary: float = 2e-3) -> Truth:
    """The events a detector must find and the clean strides' time spans (module docstring).

    `plant_events` need kind, t, z, zdot, leg_angle (sim PlantEvents, "fall" included if known);
    `toe_height_samples` are (t, toe height) of the 1 kHz true states. Strides run apex to apex;
    a clean one is exactly touchdown, bottom, lift-off (rising), apex, with at least `min_ascent`
    from lift-off to apex and the toe `min_apex_clearance` above the ground at the apex. Events
    of any other stride (a fall, a scuff, a touch, a hop too small to time) are optional.
    A clean stride's span runs from `boundary` after its opening apex (the simulator throws the
    robot right after an apex: what follows it within a period is the old trajectory) to
    `boundary` after its closing apex.
    """
    events = sorted((e for e in plant_events if e.kind in KINDS or e.kind == "fall"), key=lambda e: e.t)
    groups, current = [], []
    for event in events:
        current.append(event)
        if event.kind == "apex":
            groups.append(current)
            current = []
    if current:
        groups.append(current)
    result, spans = [], []
    start = -math.inf
    for group in groups:
        kinds = [e.kind for e in group]
        clean = kinds == ["touchdown", "bottom", "liftoff", "apex"]
        if clean:
            liftoff, apex = group[2], group[3]
            clean = (liftoff.zdot > 0.0 and apex.t - liftoff.t >= min_ascent
                     and apex.z - rest_length * math.cos(apex.leg_angle) >= min_apex_clearance)
        window_start = start
        for event in group:
            if event.kind == "fall":
                continue
            result.append(TrueEvent(KINDS[event.kind], event.t, optional=not clean))
            if event.kind == "touchdown":
                crossing = _last_crossing(toe_height_samples, pre_touchdown_height, window_start + 1.5e-3, event.t)
                if crossing is not None:
                    result.append(TrueEvent(EventType.PRE_TOUCHDOWN, crossing, optional=not clean))
                elif clean:    # the truth samples there are missing: the stride cannot be judged
                    clean = False
                    result[:] = [dataclasses.replace(e, optional=True) if e.time > window_start else e
                                 for e in result]
            window_start = event.t
        last = group[-1]
        if last.kind == "apex" and last.z - rest_length * math.cos(last.leg_angle) <= pre_touchdown_height:
            result.append(TrueEvent(EventType.PRE_TOUCHDOWN, last.t, optional=True))
        if clean:
            spans.append((start + boundary, last.t + boundary))
        start = last.t
    return Truth(sorted(result, key=lambda e: e.time), spans)


MAX_TRUTH_GAP = 0.02   # [s] samples of the truth further apart than this do not locate a crossing


def _last_crossing(samples: list[tuple[float, float]], height: float, after: float, until: float) -> float | None:
    """Time of the last downward crossing of `height` between `after` and `until` (linear between
    the samples: in a descent the toe height is nearly linear, a 10 ms gap errs by ~0.1 ms)."""
    found = None
    previous = None
    for t, value in samples:
        if t < after:
            continue
        if t > until:
            break
        if previous is not None and previous[1] > height >= value and t - previous[0] <= MAX_TRUTH_GAP:
            fraction = (previous[1] - height) / (previous[1] - value)
            found = previous[0] + fraction * (t - previous[0])
        previous = (t, value)
    return found


@dataclass
class MatchReport:
    errors: dict[EventType, list[float]]     # detected - true [s] of required events, per kind
    optional_errors: list[float]             # the same for optional events that were found
    missed: list[TrueEvent]                  # required true events without a detection
    extra: list[tuple[EventType, float]]     # detections inside clean strides matching no true event
    unconfirmed: list[tuple[EventType, float]]   # detections elsewhere matching no true event

    def max_error(self, kind: EventType | None = None) -> float:
        values = [abs(v) for k, errors in self.errors.items() if kind is None or k == kind for v in errors]
        return max(values) if values else 0.0

    def count(self, kind: EventType) -> int:
        return len(self.errors.get(kind, []))

    def summary(self) -> str:
        parts = [f"{k.name.lower()} {len(v)} (max {1e3 * max(abs(x) for x in v):.3f} ms)"
                 for k, v in sorted(self.errors.items()) if v]
        return (", ".join(parts) + f"; missed {len(self.missed)}, extra {len(self.extra)}; optional found "
                f"{len(self.optional_errors)}, unconfirmed {len(self.unconfirmed)}")


def match_events(truth: Truth, detected: Iterable[tuple[EventType, float]], window: float = 0.01) -> MatchReport:
    """Pair each detection with the nearest unpaired true event of its kind within `window` seconds."""
    detected = sorted(detected, key=lambda d: d[1])
    events = truth.events
    used: set[int] = set()
    errors: dict[EventType, list[float]] = {}
    optional_errors, extra, unconfirmed = [], [], []
    for kind, t in detected:
        best = None
        for index, true in enumerate(events):
            if index in used or true.kind != kind or abs(true.time - t) > window:
                continue
            if best is None or abs(true.time - t) < abs(events[best].time - t):
                best = index
        if best is None:
            inside = any(start <= t <= end for start, end in truth.clean_spans)
            (extra if inside else unconfirmed).append((kind, t))
            continue
        used.add(best)
        if events[best].optional:
            optional_errors.append(t - events[best].time)
        else:
            errors.setdefault(kind, []).append(t - events[best].time)
    missed = [true for index, true in enumerate(events) if index not in used and not true.optional]
    return MatchReport(errors, optional_errors, missed, extra, unconfirmed)


def detected_in_sim_time(events: Iterable, clock_offset: float = MCU_CLOCK_OFFSET) -> list[tuple[EventType, float]]:
    """(kind, simulation time) of DetectedEvents stamped on the microcontroller clock."""
    return [(event.kind, event.time - clock_offset) for event in events]


def flight_velocity_errors(estimates: Mapping[int, Any], truth: Iterable[TrueState], sequences: Iterable[int],
                           settle_after: Iterable[float] = (), settle: float = 0.03) -> list[float]:
    """z' errors (estimate - truth) in flight, per sample, leaving out `settle` seconds after each
    time in `settle_after` (throws: the filter restarts there)."""
    starts = sorted(settle_after)
    errors = []
    for sequence, state in zip(sequences, truth):
        estimate = estimates.get(sequence)
        if estimate is None or state.in_contact or state.fallen:
            continue
        if any(0.0 <= state.t - t < settle for t in starts):
            continue
        errors.append(estimate.z_dot - state.zdot)
    return errors


@dataclass
class Replay:
    """What the pipeline made of a packet stream."""

    estimates: dict[int, Any] = field(default_factory=dict)   # sequence -> the estimate that used its sample
    events: list = field(default_factory=list)                 # DetectedEvent
    predicted: int = 0                                          # estimates without a measurement


def replay(pipeline, datagrams: Iterable[bytes], receive_times: Iterable[float]) -> Replay:
    """Feed datagrams through a `SensingPipeline`; receive times on the host clock [s]."""
    result = Replay()
    for datagram, received in zip(datagrams, receive_times):
        output = pipeline.process(datagram, received)
        for estimate in output.estimates:
            if estimate.measurement_used or estimate.outlier_rejected:
                result.estimates[estimate.sequence] = estimate
            else:
                result.predicted += 1
        result.events.extend(output.events)
    return result


def inject_faults(packets: list[EncoderPacket], rng) -> tuple[list[bytes], dict[str, int], int]:
    """The packet stream as datagrams with every kind of bad input mixed in, at fixed places (every
    97 packets: truncated, garbage, a flipped bit, another format version, a duplicate, two swapped,
    a clock going backwards, three lost). Returns (datagrams, the bridge counters they must cause,
    the packets lost). `rng` is a random.Random."""
    out, expected = [], dict.fromkeys(("malformed_size", "malformed_magic", "malformed_version",
                                       "malformed_checksum", "duplicates", "reordered", "clock_backwards"), 0)
    lost = 0
    i = 0
    while i < len(packets):
        p = packets[i]
        data = packet_format.encode(p)
        roll = i % 97
        if roll == 11:                                  # truncated
            out += [data[:rng.randrange(0, 36)], data]
            expected["malformed_size"] += 1
        elif roll == 23:                                # garbage of the right size
            out += [bytes(rng.randrange(256) for _ in range(36)), data]
            expected["malformed_magic"] += 1
        elif roll == 31:                                # a bit flipped on the way
            broken = bytearray(data)
            broken[rng.randrange(4, 32)] ^= 1 << rng.randrange(8)
            out += [bytes(broken), data]
            expected["malformed_checksum"] += 1
        elif roll == 41:                                # another firmware's packet
            out += [packet_format.encode(dataclasses.replace(p, version=2)), data]
            expected["malformed_version"] += 1
        elif roll == 53:                                # delivered twice
            out += [data, data]
            expected["duplicates"] += 1
        elif roll == 61 and i + 1 < len(packets):       # two packets swapped: the older one comes late
            out += [packet_format.encode(packets[i + 1]), data]
            expected["reordered"] += 1
            lost += 1
            i += 1
        elif roll == 71 and i + 1 < len(packets):       # a valid packet whose clock went backwards
            step_back = dataclasses.replace(packets[i + 1], mcu_time_us=p.mcu_time_us - 500)
            out += [data, packet_format.encode(step_back)]
            expected["clock_backwards"] += 1
        elif roll == 83:                                # three packets lost
            lost += 3
            i += 3
            continue
        else:
            out.append(data)
        i += 1
    return out, expected, lost


def receive_times(datagrams: Iterable[bytes]) -> list[float]:
    """Host receive times: the microcontroller clock of each intact packet (the last one's for the rest)."""
    times, last = [], 0.0
    for data in datagrams:
        try:
            last = max(last, packet_format.decode(data).mcu_time_us * 1e-6)
        except packet_format.PacketError:
            pass
        times.append(last)
    return times
