"""Proof of the mismatch tool (issue 9): recordings of the simulated robot with one effect the
model lacks, every sensor noise on, CSV without phase labels; the tool must name the effect and
its magnitude within 20 %, and say "no significant mismatch" when nothing is missing."""

import numpy as np
import pytest

from hopper_ros.config import load_yaml
from hopper_ros.diagnosis import DiagnosisError, diagnose_file
from hopper_ros.identification.recordings import Recording, load_csv
from hopper_ros.recording.collect import CollectionSettings, collect
from hopper_ros.sim.config import SENSORS, load_sim_config

STRIDES = 20
# effect switched on in the simulated robot -> (sim settings, name expected, true magnitude)
CASES = {
    "leg_friction": ({"leg_friction": True}, "leg_friction", 2.0),
    "ground_compliance": ({"ground_compliance": True}, "ground_compliance", 60000.0),
    "touchdown_loss_across": ({"touchdown_loss_across": True}, "touchdown_loss_across", 0.06),
    "torque_saturation": ({"torque_saturation": True}, "torque_saturation", 4.0),
    "actuation_delay": ({"actuation_delay": True}, "actuation_delay", 0.004),
    "effective_gravity": ({"effective_gravity": {"g": 10.6}}, "effective_gravity", 10.6),
}


def make_recording(tmp_path, effects):
    cfg = load_sim_config().with_sensors(**{n: True for n in SENSORS})
    if effects:
        cfg = cfg.with_effects(**effects)
    c = collect(tmp_path / "bag", cfg, load_yaml("hardware.yaml"), CollectionSettings(strides=STRIDES, seed=3),
                csv_path=tmp_path / "run.csv")
    return c.csv


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = {}
    for case, (effects, _, _) in [("none", (None, None, None)), *CASES.items()]:
        path = make_recording(tmp_path_factory.mktemp(case), effects)
        rec = load_csv(path)
        assert rec.phase is None or np.all(rec.phase == -1)     # nothing labelled
        out[case] = diagnose_file(rec, output=tmp_path_factory.mktemp(case + "_report") if case == "none" else None)
    return out


def test_negative_control(results):
    r = results["none"]
    assert r["verdict"] == "no significant mismatch"
    assert r["chosen"] == []
    assert (r["report"]).is_file() and (r["report"].parent / "diagnosis.png").is_file()
    assert "no significant mismatch" in r["report"].read_text()


@pytest.mark.parametrize("case", list(CASES))
def test_names_effect_and_magnitude(results, case):
    _, expected, truth = CASES[case]
    r = results[case]
    assert r["chosen"], f"{case}: nothing named; ranking {[(x['name'], x['reduction']) for x in r['rounds'][0][:3]]}"
    first = r["chosen"][0]
    assert first["name"] == expected, r["verdict"]
    assert abs(first["magnitude"] - truth) <= 0.2 * truth, (first["magnitude"], truth)
    if case != "effective_gravity":   # known limitation: g's fit leaves a flight-damping correction (docs/diagnosis.md)
        assert len(r["chosen"]) == 1, r["verdict"]
    # the chosen effect makes the held-out predictions better
    assert r["after"]["E_v"] < r["before"]["E_v"]


def test_bad_inputs(tmp_path):
    t = np.arange(0, 2, 0.002)
    rec = Recording(t, t, np.full_like(t, 0.4), np.zeros_like(t), np.zeros_like(t), source="slow")
    with pytest.raises(DiagnosisError, match="1 kHz"):
        diagnose_file(rec)
    t = np.arange(0, 2, 0.001)
    rec = Recording(t, t, np.full_like(t, 0.4), np.zeros_like(t), np.zeros_like(t), source="flat")
    with pytest.raises(DiagnosisError, match="strides"):
        diagnose_file(rec)
    bad = tmp_path / "bad.csv"
    bad.write_text("t,y,z\n0,0,0\n")
    with pytest.raises(ValueError):
        diagnose_file(bad)
