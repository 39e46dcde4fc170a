"""Scores `hopper diagnose` on recordings of the independent plant (test/independent_plant/).

The plant writes, beside each recording, what it concealed (its own parameterisation). This module
says what a right answer is: for an effect a library entry models, that entry named (or reported
as not separable from the one named) with its magnitude within 20 % once converted to the
library's parameter; for an effect no entry models, a discovered term set at the site where it acts.
A verdict that matches no concealed effect is a false positive. Used by test_diagnosis_independent.py
(a subset) and bench_diagnosis.py (the whole suite).
"""

from __future__ import annotations

import json
import multiprocessing
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
NOMINAL = {"d_v": 0.23, "d_h": 0.01, "k": 4696.0, "rho_0": 0.205}
# plant effect id -> (library entry, magnitude in the entry's unit from the plant's magnitude)
LIBRARY_MATCH = {
    "air_drag_quadratic": ("quadratic_drag", lambda m: m),
    "boom_bearing_coulomb": ("boom_friction_horizontal", lambda m: m),
    "flight_damping_vertical_extra": ("flight_damping_vertical", lambda m: NOMINAL["d_v"] + m),
    "flight_damping_horizontal_extra": ("flight_damping_horizontal", lambda m: NOMINAL["d_h"] + m),
    "effective_gravity": ("effective_gravity", lambda m: m),
    "boom_horizontal_inertia": ("horizontal_inertia", lambda m: m),
    "touchdown_loss_along": ("touchdown_loss_along", lambda m: m),
    "touchdown_loss_across": ("touchdown_loss_across", lambda m: m),
    "stiffness_error": ("leg_stiffness", lambda m: NOMINAL["k"] + m),
    # the plant's spring is longer than its leg stop: a preload k delta_rho (the leg's length is unchanged)
    "spring_rest_length_error": ("spring_preload", lambda m: NOMINAL["k"] * m),
    "spring_cubic": ("spring_cubic", lambda m: m),
    "leg_damping_quadratic": ("quadratic_leg_damping", lambda m: m),
    "leg_slide_coulomb": ("leg_friction", lambda m: m),
    "compliant_ground": ("ground_compliance", lambda m: m),
    "actuator_gain": ("torque_gain", lambda m: m),
    "actuator_offset": ("torque_offset", lambda m: m),
    "actuator_delay": ("actuation_delay", lambda m: m),
    "actuator_lag": ("actuator_lag", lambda m: m),
    "actuator_saturation": ("torque_saturation", lambda m: m),
    "hip_friction_viscous": ("hip_viscous_friction", lambda m: m),
    "hip_friction_coulomb": ("hip_dry_friction", lambda m: m),
    "liftoff_toe_mass": ("liftoff_collision", lambda m: m),
    "ground_higher": ("ground_height", lambda m: m),
    # the plant's kinetic friction (its static one is a little higher; the library has one mu)
    "toe_slip": ("toe_slip", lambda m: m),
    "sensor_delay_z": ("z_delay", lambda m: m), "sensor_delay_y": ("y_delay", lambda m: m),
    "sensor_delay_theta": ("theta_delay", lambda m: m),
    "sensor_scale_z": ("z_scale", lambda m: m), "sensor_scale_y": ("y_scale", lambda m: m),
    "sensor_scale_theta": ("theta_scale", lambda m: m),
    "sensor_offset_z": ("z_offset", lambda m: m), "sensor_offset_theta": ("theta_offset", lambda m: m),
}
# the plant's site -> the located / discovered sites that are right for it
SITES = {"flight": {"flight_horizontal", "flight_vertical"},
         "touchdown": {"touchdown_along", "touchdown_across", "touchdown_timing"},
         "stance_along_leg": {"stance_along", "stance_hip"}, "stance_hip": {"stance_hip"},
         "actuator": {"stance_hip"}, "liftoff": {"liftoff_along", "liftoff_across"},
         "sensor_z": {"flight_vertical", "flight_horizontal", "stance_along", "stance_hip", "touchdown_along",
                      "touchdown_across", "liftoff_along", "liftoff_across", "touchdown_timing"}}
SITES["sensor_y"] = SITES["sensor_theta"] = SITES["sensor_z"]
TOLERANCE = 0.2
# The sweeps diagnose two recordings at a time, each in a process of its own with one numba thread: a diagnosis
# is two thirds single-threaded Python (the search, the fits), so one at a time with two numba threads left a core
# idle most of the time. A recording's verdict does not depend on it (the lanes are independent).
WORKERS = 2


def _expected(effect: dict):
    if "library" in effect:          # a recording of our own simulated robot names the entry itself
        return effect["library"], float(effect["magnitude"])
    match = LIBRARY_MATCH.get(effect["id"])
    if match is None:
        return None, None
    name, convert = match
    return name, convert(float(effect["magnitude"]))


def score(result, truth: dict, threshold: float) -> dict:
    """Hits, misses, false positives and location hits of one diagnosis (`records.Diagnosis`) against its truth
    sidecar."""
    verdicts = list(result.chosen)
    used = set()
    hits, misses, located = [], [], []
    for effect in truth["effects"]:
        name, magnitude = _expected(effect)
        right_sites = set(effect["located_sites"]) if "located_sites" in effect else SITES.get(effect["site"], set())
        found = None
        for k, r in enumerate(verdicts):
            c = r.candidate
            names = {c.name, *(t.name for t in r.ties)}
            if name is not None and name in names:
                mag = r.magnitude if c.name == name else next(t.magnitude for t in r.ties if t.name == name)
                if abs(mag - magnitude) <= TOLERANCE * abs(magnitude):
                    found = (k, f"{name} {mag:.4g} (true {magnitude:.4g})")
                    break
            if name is None:   # an effect no entry models: terms discovered where it acts (or among the look-alikes)
                options = [r] + list(r.ties)
                hit = next((o for o in options if o.candidate.kind == "discovered"
                            and o.candidate.site in right_sites), None)
                if hit is not None:
                    found = (k, f"{hit.name}: {hit.candidate.describe(hit.value)}")
                    break
        if found:
            used.add(found[0])
            hits.append((effect["id"], found[1]))
        else:
            misses.append((effect["id"], name, magnitude))
        above = {loc.site for loc in result.location if loc.ratio >= threshold}
        if effect["site"].startswith("sensor") or above & right_sites:
            located.append(effect["id"])
    false = [r.name for k, r in enumerate(verdicts) if k not in used]
    return {"hits": hits, "misses": misses, "false_positives": false, "located": located,
            "effects": len(truth["effects"]), "clean": not truth["effects"],
            "physics_only": not any(e["site"].startswith("sensor") for e in truth["effects"])}


def dependence_found(result, effect: dict, forms: set, used: set, tolerance: float = 0.25):
    """The index and words of a dependence on the track position (`diagnosis.dependence`) of one of `forms` with
    the concealed effect's magnitude within `tolerance` and not yet `used` (it is then), or None."""
    want = float(effect["magnitude"])
    for k, d in enumerate(result.dependences):
        if k not in used and d.form in forms and abs(d.magnitude - want) <= tolerance * abs(want):
            used.add(k)
            return k, f"dependence ({d.form}) {1e3 * d.magnitude:.1f} mm (true {1e3 * want:.1f} mm)"
    return None


def independent_score(result, truth: dict) -> dict:
    from hopper_ros.diagnosis.report import location_line
    from hopper_ros.diagnosis.settings import Settings

    threshold = Settings().locate_threshold
    row = score(result, truth, threshold)
    row["location"] = location_line(result.location, threshold)
    return row


def independent_line(s: dict) -> str:
    return (f"{s['name']}: {len(s['hits'])}/{s['effects']} named, false {s['false_positives']}, located "
            f"{len(s['located'])}, {s['seconds']:.0f} s | {s['verdict']} | {s['location']}")


def _diagnosed_row(job) -> dict:
    """A worker's job: (name, recording, truth, score) diagnosed and scored, the row of a summary."""
    from hopper_ros.diagnosis import diagnose_file

    name, recording, truth, score_one = job
    result = diagnose_file(recording)
    row = score_one(result, truth)
    row.update(name=name, seconds=result.wall_time, verdict=result.verdict, before=result.before.as_dict(),
               after=result.after.as_dict())
    return row


def diagnosed_rows(jobs: list, line, verbose: bool = True) -> list[dict]:
    """Each job (name, recording, truth, score: a module-level `score(result, truth) -> row`) diagnosed and
    scored, `WORKERS` at a time in processes of one numba thread each; `line(row)` printed as each row comes,
    in order. The rows, in the jobs' order."""
    if len(jobs) <= 1:
        rows = [_diagnosed_row(job) for job in jobs]
        for row in rows if verbose else ():
            print(line(row), flush=True)
        return rows
    saved = os.environ.get("NUMBA_NUM_THREADS")
    os.environ["NUMBA_NUM_THREADS"] = "1"          # read by each worker's numba at its import
    try:
        with ProcessPoolExecutor(WORKERS, mp_context=multiprocessing.get_context("spawn")) as pool:
            rows = []
            for row in pool.map(_diagnosed_row, jobs):
                if verbose:
                    print(line(row), flush=True)
                rows.append(row)
            return rows
    finally:
        if saved is None:
            os.environ.pop("NUMBA_NUM_THREADS", None)
        else:
            os.environ["NUMBA_NUM_THREADS"] = saved


def diagnose_and_score(name: str, recording, truth: dict, verbose: bool = True) -> dict:
    """One recording diagnosed and scored: the row of a summary."""
    return diagnosed_rows([(name, recording, truth, independent_score)], independent_line, verbose)[0]


def _truths(folder: Path, names) -> list[tuple[str, Path, dict]]:
    """(name, recording, truth) of each recording of `folder` (CSV + truth JSON, `names` only if given)."""
    return [(path.stem, path.with_suffix(".csv"), json.loads(path.read_text()))
            for path in sorted(folder.glob("*.json"))
            if not (names and path.stem not in names or path.stem == "score")]   # (a scorer's own output)


def score_folder(folder: Path, names, score, line, verbose: bool = True) -> list[dict]:
    """Each recording of `folder` (CSV + truth JSON, `names` only if given) diagnosed and scored by
    `score(result, truth)` (module-level: it runs in the workers); `line(row)` is printed per recording when
    verbose. The rows."""
    return diagnosed_rows([(name, csv, truth, score) for name, csv, truth in _truths(folder, names)], line, verbose)


def summarise(rows: list[dict]) -> dict:
    """Hit, false-positive and locate rates over scored rows; recordings whose held-out apex got worse."""
    from hopper_ros.physics import effects as library

    effects = sum(r["effects"] for r in rows)
    named = sum(len(r["hits"]) for r in rows)
    false = sum(len(r["false_positives"]) for r in rows)
    worse = [r["name"] for r in rows if any(r["after"][k] > r["before"][k] * 1.01 + 1e-6 for k in ("E_p", "E_v", "E_t"))]
    return {"rows": rows, "hit_rate_pct": 100.0 * named / max(effects, 1),
            "false_positive_pct": 100.0 * false / max(named + false, 1),
            "locate_hit_rate_pct": 100.0 * sum(len(r["located"]) for r in rows) / max(effects, 1),
            "sensor_on_physics": sum(1 for r in rows if r["physics_only"] for f in r["false_positives"]
                                     if f in library.EFFECTS and library.get(f).kind == "sensor"),
            "pair_hit_rate_pct": 100.0 * sum(len(r["hits"]) for r in rows if r["effects"] >= 2)
            / max(sum(r["effects"] for r in rows if r["effects"] >= 2), 1),
            "clean_ok": all(not r["false_positives"] for r in rows if r["clean"]), "worse_after": worse,
            "recordings": len(rows), "effects": effects}


def run(folder: Path, names=None, verbose=True) -> dict:
    """Diagnose every recording of `folder` (CSV + truth JSON) and sum the scores."""
    return summarise(score_folder(folder, names, independent_score, independent_line, verbose))


def suite(score, summarise, line):
    """The `run(folder, names=None, verbose=True)` of a blind plant's scorer: `score_folder` then `summarise`."""
    def run(folder: Path, names=None, verbose: bool = True) -> dict:
        return summarise(score_folder(folder, names, score, line, verbose))
    return run


def main(run, argv: list[str]) -> None:
    """`SCORER FOLDER [NAME ...]`: `run`'s summary printed (rows left out) and kept in FOLDER/score.json."""
    if len(argv) < 2 or not Path(argv[1]).is_dir():
        raise SystemExit(f"usage: {Path(argv[0]).name} FOLDER [NAME ...]  (FOLDER: a suite's recordings)")
    summary = run(Path(argv[1]), argv[2:] or None)
    print(json.dumps({k: v for k, v in summary.items() if k != "rows"}, indent=1))
    (Path(argv[1]) / "score.json").write_text(json.dumps(summary, indent=1, default=str))


if __name__ == "__main__":
    sys.path.insert(0, str(REPO / "test"))
    main(run, sys.argv)
