"""The mismatch tool on the simulated robot (issue 14): recordings of 50 strides with one library effect
(or a pair from different phases) switched on in the simulated robot, every sensor noise on, CSV
without phase labels; the tool must name each effect with its magnitude within 20 %, locate it where it
acts, name nothing on a clean recording and no sensor fault on a physics-only one. A representative
subset here; every entry in `make bench` (bench/diagnosis_sim_sweep.py)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hopper_ros.diagnosis import DiagnosisError, diagnose_file
from hopper_ros.diagnosis.report import location_line
from hopper_ros.diagnosis.settings import Settings
from hopper_ros.recording.recordings import Recording, write_csv
from hopper_ros.physics import effects as library

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
from diagnosis_sim_sweep import cases, make_recording  # noqa: E402
from diagnosis_suite import score  # noqa: E402

pytestmark = pytest.mark.compute   # CPU-bound: `make test` runs these beside the node tests (tools/test.sh)

# touchdown_loss_across: too small to stand above noise by force, one stride at a time; located by fit.
# The pair: a loss at touchdown and a viscous hip friction in stance (11 s). The gravity beside an actuation delay (a
# constant flight force discovered first gives way to the gravity when revisited beside the delay: 88 s) is in
# `make bench`'s sweep.
SUBSET = ("clean_a", "quadratic_drag", "touchdown_loss_along", "effective_gravity", "touchdown_loss_across",
          "touchdown_loss_along+hip_viscous_friction")


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = {}
    table = cases()
    for name in SUBSET:
        folder = tmp_path_factory.mktemp(name.replace("+", "_"))
        rec, truth = make_recording(table[name], folder, seed=100 + list(table).index(name))   # as the sweep
        csv = write_csv(folder / "input.csv", rec)
        result = diagnose_file(csv, output=folder / "report" if name == "clean_a" else None)
        out[name] = (rec, truth, result, score(result, truth, Settings().locate_threshold), csv)
    return out


@pytest.mark.parametrize("name", SUBSET)
def test_named_with_magnitude_and_nothing_else(results, name):
    _, truth, result, s, _ = results[name]
    assert not s["misses"], f"{name}: missed {s['misses']}; verdict {result.verdict}"
    assert not s["false_positives"], f"{name}: {result.verdict}"
    for r in result.chosen:
        assert r.candidate.kind != "sensor", f"a sensor fault named on a physics-only recording: {r.name}"
    # what the named effects leave is what noise leaves: said in the verdict
    assert result.completeness.explained, (result.verdict, result.completeness)
    assert result.chosen == [] or "; explained" in result.verdict


@pytest.mark.parametrize("name", [n for n in SUBSET if n != "clean_a"])
def test_located_where_it_acts_and_fit_improves(results, name):
    _, truth, result, s, _ = results[name]
    assert len(s["located"]) == len(truth["effects"]), [loc.words() for loc in result.location[:3]]
    for key in ("E_p", "E_v", "E_t"):
        assert getattr(result.after, key) <= getattr(result.before, key) * 1.01 + 1e-6
    assert result.after.E_p < result.before.E_p


def test_small_touchdown_loss_located_by_fit(results):
    """The force residual at touchdown is within the noise; the re-simulations of the naming locate it."""
    result = results["touchdown_loss_across"][2]
    at = [loc for loc in result.location if loc.site == "touchdown_across"
          and loc.ratio >= Settings().locate_threshold]
    assert at and at[0].basis == "fit" and at[0].window == "touchdown_loss_across", [
        loc.words() for loc in result.location[:4]]
    assert "(by fit: touchdown_loss_across removes" in location_line(result.location, Settings().locate_threshold)


def test_clean_recording_nothing_located_report_written(results):
    _, _, result, _, _ = results["clean_a"]
    assert result.verdict == "no significant mismatch"
    assert all(loc.ratio < Settings().locate_threshold for loc in result.location)
    report = result.report
    assert report.is_file() and (report.parent / "diagnosis.png").is_file()
    assert "no significant mismatch" in report.read_text()


def test_cli_lines_and_json(results, tmp_path):
    _, _, _, _, csv = results["quadratic_drag"]
    out = tmp_path / "verdict.json"
    proc = subprocess.run([sys.executable, "-m", "hopper_ros.cli", "diagnose", str(csv), "--json", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert any(line.startswith("location: flight, horizontal") for line in lines), proc.stdout
    assert any(line.startswith("missing: quadratic_drag") for line in lines), proc.stdout
    doc = json.loads(out.read_text())
    entry = doc["verdict"][0]
    assert entry["name"] == "quadratic_drag" and entry["kind"] == "physics" and entry["unit"] == "1/m"
    assert entry["held_out_after"]["E_p"] < entry["held_out_before"]["E_p"]
    assert doc["location"][0]["phase"] == "flight" and doc["location"][0]["above_noise"]


def test_every_library_entry_has_a_sweep_case():
    table = cases()
    for e in library.LIBRARY + library.SENSORS:
        assert [e.name] in table.values(), e.name
    assert sum(1 for v in table.values() if len(v) == 2) >= 4 and sum(1 for v in table.values() if not v) == 2


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
    model = tmp_path / "model.yaml"
    model.write_text("model: {body_mass: 2.2, toe_mass: 0.03, gravity: 11.42, stiffness: 4696, damping: 9.87, "
                     "flight_damping_horizontal: 0.01, flight_damping_vertical: 0.23, rest_length: 0.205}\n"
                     "effects: {warp_drive: 1.0}\n")
    proc = subprocess.run([sys.executable, "-m", "hopper_ros.cli", "diagnose", str(bad), "--model", str(model)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr


def test_the_researchers_loop_with_files_alone(results, tmp_path):
    """diagnose names the effect -> identify fits it into a model file -> diagnose with that model finds nothing
    and the held-out next apex is predicted better than with the plain model."""
    _, _, first, _, csv = results["quadratic_drag"]
    name = first.chosen[0].name
    proc = subprocess.run([sys.executable, "-m", "hopper_ros.cli", "identify", str(csv), "--effects", name,
                           "--folds", "3", "-o", str(tmp_path / "id")], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    model = tmp_path / "id" / "identified_model.yaml"
    assert name in model.read_text()
    again = diagnose_file(csv, model=str(model))
    assert again.model_effects and name in again.model_effects
    assert not any(r.name == name for r in again.chosen), again.verdict
    assert again.before.E_p < first.before.E_p


def test_a_secondary_parameter_is_held_and_said():
    """The ground's damping is a secondary parameter of its compliance: a candidate holding it builds models
    with that damping at every magnitude, and its words and the verdict say the value."""
    from hopper_ros.diagnosis.candidates import library_candidate
    from hopper_ros.diagnosis.core import base_variant
    from hopper_ros.diagnosis.records import Errors, Fit, Scored
    from hopper_ros.diagnosis.report import verdict
    from hopper_ros.physics.params import load_params

    base = base_variant(load_params())
    candidate = library_candidate(library.get("ground_compliance"), base.coefficients)
    (damping,) = candidate.secondary
    assert damping.coefficient == "ground_damping" and candidate.held == {}
    held = candidate.holding(damping, 150.0)
    for value in (1e-5, 5e-5):
        built = held.build(base, value).coefficients
        assert built.ground_damping == 150.0 and built.ground_stiffness == pytest.approx(1.0 / value)
    assert candidate.build(base, 1e-5).coefficients.ground_damping == base.coefficients.ground_damping
    assert "d_g = 150 N s/m" in held.describe(1e-5)
    line = verdict([Scored(held, Fit(2.5e-5, [], [], [], np.zeros(0)), 4e4, np.ones(1), Errors(0.0, 0.0, 0.0, 0))])
    assert line == "missing: ground_compliance = 4e+04 N/m (d_g 150 N s/m)", line
