"""Plant C's suite of recordings: each mechanism alone, two pairs, two clean recordings.

    python test/plant_c/suite.py OUT_DIR [names...]

writes OUT_DIR/<name>.csv (t,y,z,theta,tau at 1 kHz; runs separated by gaps >= 1 s) and
OUT_DIR/<name>.json (the truth).  Deterministic: every case has its own fixed seed.
"""

from __future__ import annotations

import json
import sys
import time
from multiprocessing import Pool
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from controller import ENVELOPE_V, ENVELOPE_Z, Controller  # noqa: E402
from effects import REGISTRY, make  # noqa: E402
from plant import DT, Plant, StrideFailure, concat, nominal_params  # noqa: E402

STRIDES = 50
RUN_STRIDES = (7, 14)       # strides per run (a throw), drawn; fewer if a stride fails
GAP = (1.5, 2.0)            # [s] no samples between runs (the robot caught and thrown again)

SINGLES = list(REGISTRY)
PAIRS = [("round_foot", "motor_back_emf"), ("air_chamber", "azimuth_eccentricity")]


def _cases() -> dict:
    cases = {"clean_a": ([], 1001), "clean_b": ([], 1002)}
    for i, mid in enumerate(SINGLES):
        cases[mid] = ([mid], 2001 + i)
    for i, pair in enumerate(PAIRS):
        cases["pair_" + "+".join(pair)] = (list(pair), 3001 + i)
    return cases


CASES = _cases()


def simulate(name: str, ids: list[str], seed: int, strides: int = STRIDES,
             mechanisms=None, params=None):
    """One recording: returns (measured channels, truth dict, log of strides)."""
    p = params or nominal_params()
    rng = np.random.default_rng(seed)
    mechs = mechanisms if mechanisms is not None else [make(i) for i in ids]
    plant = Plant(p, mechs, seed=seed + 1)
    ctl = Controller(p, np.random.default_rng(seed + 2))
    t, y = 0.0, 0.0
    blocks, log = [], []
    done, throws = 0, 0
    while done < strides:
        throws += 1
        if throws > 4 * strides:
            raise RuntimeError(f"{name}: the robot keeps failing")
        z0, v0 = ctl.throw_state()
        ctl._countdown = 0
        cmd = ctl.plan(z0, v0)
        plant.throw(t, y, z0, v0, cmd.theta_td)
        want = min(int(rng.integers(*RUN_STRIDES)), strides - done)
        run, k = [], 0
        while k < want:
            def plan_next(t_lo, y_lo, z_lo, vy, vz):
                return ctl.at_liftoff(z_lo, vy, vz)[0]
            swing_end = plant.swing.t_end
            try:
                r = plant.stride(cmd, plan_next)
            except StrideFailure as exc:
                log.append(dict(run=throws, failure=str(exc)))
                break
            run += r["samples"]
            k += 1
            a = r["apex_next"]
            log.append(dict(run=throws, z_apex=a["z"], v_apex=a["vy"], theta_td=cmd.theta_td,
                            tau0=cmd.tau0, t_f=cmd.t_f, t_stance=r["t_lo"] - r["t_td"],
                            hold=r["t_td"] - swing_end, floor=r["touchdown"]["floor"]))
            cmd = plant.cmd_next
            if not (ENVELOPE_Z[0] - 0.02 < a["z"] < ENVELOPE_Z[1] + 0.02
                    and ENVELOPE_V[0] - 0.2 < a["vy"] < ENVELOPE_V[1] + 0.2):
                break
        if k == 0:
            t += 1.0
            continue
        run.append(plant.final_sample())
        blocks += run
        done += k
        t_last = run[-1]["t"][-1]
        y = float(run[-1]["y"][-1]) + float(rng.uniform(-0.3, 0.8))
        t = round((t_last + rng.uniform(*GAP)) / DT) * DT
    ch = concat(blocks)
    meas = plant.measure(ch, np.random.default_rng(seed + 3))
    truth = {"name": name, "effects": [m.truth() for m in mechs], "strides": int(done),
             "seed": int(seed)}
    return meas, truth, log


def write(out_dir: Path, name: str, meas: dict, truth: dict) -> None:
    out_dir.mkdir(parents=True, exist_ok=True)
    data = np.column_stack([meas["t"], meas["y"], meas["z"], meas["theta"], meas["tau"]])
    np.savetxt(out_dir / f"{name}.csv", data, delimiter=",", header="t,y,z,theta,tau",
               comments="", fmt=["%.3f", "%.7f", "%.7f", "%.8f", "%.6f"])
    (out_dir / f"{name}.json").write_text(json.dumps(truth, indent=1) + "\n")


def _job(args):
    out_dir, name = args
    ids, seed = CASES[name]
    t0 = time.time()
    meas, truth, log = simulate(name, ids, seed)
    write(Path(out_dir), name, meas, truth)
    ok = [e for e in log if "z_apex" in e]
    fails = [e["failure"] for e in log if "failure" in e]
    z = [e["z_apex"] for e in ok]
    v = [e["v_apex"] for e in ok]
    tau = [e["tau0"] for e in ok]
    th = [e["theta_td"] for e in ok]
    return (f"{name:42s} strides {truth['strides']:3d} runs {len(set(e['run'] for e in ok)):2d} "
            f"fail {len(fails)}  apex z {min(z):.3f}-{max(z):.3f}  v {min(v):.2f}-{max(v):.2f}"
            f"  tau0 {min(tau):.1f}-{max(tau):.1f}  th_td {min(th):.2f}-{max(th):.2f}"
            f"  hold >= {1e3 * min(e['hold'] for e in ok):.0f} ms"
            f"  {time.time() - t0:5.1f} s")


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__)
        print("cases:", " ".join(CASES))
        return 2
    out_dir = Path(argv[0])
    names = argv[1:] or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print("unknown cases:", unknown, "\nknown:", " ".join(CASES))
        return 2
    t0 = time.time()
    with Pool(min(2, len(names))) as pool:
        for line in pool.imap_unordered(_job, [(str(out_dir), n) for n in names]):
            print(line, flush=True)
    print(f"{len(names)} recordings in {time.time() - t0:.1f} s -> {out_dir}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
