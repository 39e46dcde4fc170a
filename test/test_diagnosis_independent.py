"""The mismatch tool judged by a plant it was not built with (issue 15): test/independent_plant/ was
written from the thesis apart from the effect library and the diagnosis engine, with its own
equations, integrator (solve_ivp with event location), stride controller, encoders and noise; its
logs hold the commanded torque and no phase labels. A representative subset runs here; the whole
suite (`bench/bench_diagnosis.py`) in `make bench`."""

import json
import sys
from pathlib import Path

import pytest

from hopper_ros.diagnosis import diagnose_file
from hopper_ros.diagnosis.settings import Settings

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
from diagnosis_suite import score  # noqa: E402
import stored_recordings  # noqa: E402

pytestmark = pytest.mark.compute   # CPU-bound: `make test` runs these beside the node tests (tools/test.sh)

SUBSET = ("clean_1", "flight_air_drag", "actuator_saturation", "leg_slide_coulomb", "leg_rest_length", "boom_gravity",
          "other_tether", "other_boom_bending", "sensor_y_scale")
# make test's budget: the lift in flight, the higher ground, the z delay and the toe slip (35-45 s a diagnosis, each
# partly explained and searched by every stage) are diagnosed by `make bench` with the other 30; the boom's gravity
# (8 s) stands for the lift in test_json_verdict (a discovered look-alike in flight, vertical), the y scale (5 s) for
# the sensor faults
# the pairs and the hip's torsion spring, which restart the rounds: test_diagnosis_independent_pairs.py (a module of
# their own, so that `make test` runs them in its other compute session, tools/test.sh)


def diagnosed(folder: Path, names: tuple) -> dict:
    """name -> (truth, diagnosis, score, folder) of the independent plant's recordings `names`, written to `folder`
    (the verdict's JSON beside each)."""
    stored_recordings.independent(folder, names)
    out = {}
    for name in names:
        truth = json.loads((folder / f"{name}.json").read_text())
        result = diagnose_file(folder / f"{name}.csv", json_path=folder / f"{name}.verdict.json")
        out[name] = (truth, result, score(result, truth, Settings().locate_threshold), folder)
    return out


@pytest.fixture(scope="module")
def suite(tmp_path_factory):
    return diagnosed(tmp_path_factory.mktemp("independent"), SUBSET)


def named_and_nothing_else(suite: dict, name: str) -> None:
    truth, result, s, _ = suite[name]
    assert not s["misses"], f"{name}: missed {s['misses']}; verdict: {result.verdict}"
    assert not s["false_positives"], f"{name}: named what is not there {s['false_positives']}; {result.verdict}"


def held_out_apex_never_worse(suite: dict, name: str) -> None:
    _, result, _, _ = suite[name]
    for key in ("E_p", "E_v", "E_t"):
        assert getattr(result.after, key) <= getattr(result.before, key) * 1.01 + 1e-6, (key, result.before, result.after)


def located_where_it_acts(suite: dict, name: str) -> None:
    """By force or, where the residual is within the noise one stride at a time (a torque limit clips only the
    start of some stances), by fit."""
    truth, result, s, _ = suite[name]
    if truth["effects"]:
        assert s["located"], f"{name}: not located ({[l.words() for l in result.location[:3]]})"
    else:
        assert all(loc.ratio < Settings().locate_threshold for loc in result.location), name


def pytest_generate_tests(metafunc):
    """`name`: each recording of the collecting module's SUBSET (test_diagnosis_independent_pairs.py imports the
    three tests that take it, with a SUBSET of its own)."""
    if "name" in metafunc.fixturenames:
        metafunc.parametrize("name", metafunc.module.SUBSET)


def test_every_concealed_effect_named_and_nothing_else(suite, name):
    named_and_nothing_else(suite, name)


def test_held_out_apex_never_worse(suite, name):
    held_out_apex_never_worse(suite, name)


def test_located_where_the_effects_act(suite, name):
    located_where_it_acts(suite, name)


def test_json_verdict(suite):
    """A discovered term set is written with its terms in SI units, beside the library effect it cannot be told
    apart from on this data, with the experiment that would separate them."""
    truth, result, _, folder = suite["boom_gravity"]
    doc = json.loads((folder / "boom_gravity.verdict.json").read_text())
    entry = doc["verdict"][0]
    found = [e for e in [entry, *entry["look_alikes"]] if e["kind"] == "discovered"]
    assert found and found[0]["site"] == "flight_vertical", entry
    assert found[0]["terms"] and all(t["unit"] for t in found[0]["terms"])
    assert entry["to_separate"]
    assert {"E_p", "E_v", "E_t"} <= set(entry["held_out_before"]) and entry["held_out_after"]["E_p"] <= \
        entry["held_out_before"]["E_p"]
    assert doc["location"][0]["phase"] == "flight" and doc["location"][0]["above_noise"]
    clean = json.loads((folder / "clean_1.verdict.json").read_text())
    assert clean["verdict"] == [] and clean["summary"] == "no significant mismatch"


def test_stance_start_from_the_held_leg(suite, tmp_path):
    """With the running surface 8 mm above where the model has it, stance begins before the model's leg reaches
    the ground: the tool reads theta_td where the held leg starts to turn (not the angle already in stance) and
    times the ramp from there. (The ground's height is named in `make bench`'s diagnosis of the whole suite: 34 s.)"""
    from hopper_ros.diagnosis.data import prepare
    from hopper_ros.physics.params import load_model
    from hopper_ros.recording.recordings import load_recording

    stored_recordings.independent(tmp_path, ("other_ground_higher",))
    settings, (params, _) = Settings(), load_model("model.yaml")
    higher = prepare(load_recording(tmp_path / "other_ground_higher.csv"), params, settings.min_strides,
                     settings.liftoff_window)
    _, clean, _, _ = suite["clean_1"]
    assert 0.003 < higher.touchdown_lead < 0.005, higher.touchdown_lead
    assert abs(clean.data.touchdown_lead) < 0.001, clean.data.touchdown_lead


def _effect(truth):
    return truth["effects"][0]["parameters"]


def test_a_force_that_engages_above_a_height_is_found_with_its_knot(suite):
    """A tether taut above z_c pulls only the highest apexes down: no library entry models it, the residual's
    t over strides is weak (most strides never reach z_c). Discovery chooses the hinge's knot by
    cross-validation and the refitted term names both the height and the stiffness."""
    truth, result, s, _ = suite["other_tether"]
    entry = result.chosen[0]
    found = entry.candidate.discovery
    assert found is not None and found.site == "flight_vertical", result.verdict
    terms = {key: coef * entry.value for key, coef, _, _ in found.terms()}
    assert set(terms) == {"z>z_k"}, terms
    stiffness = _effect(truth)["kappa"] * truth["model"]["m_b"]
    assert abs(-terms["z>z_k"] - stiffness) <= 0.2 * stiffness, (terms, stiffness)
    assert abs(found.knot - _effect(truth)["z_c"]) <= 0.01, found.knot
    assert f"z_k = {found.knot:.3g} m" in result.verdict


def test_a_ringing_channel_is_modelled_as_what_the_sensor_sees(suite):
    """The boom's bending after lift-off is in the elevation encoder, not in the body's motion: found as a
    decaying oscillation after lift-off, its frequency, decay and amplitude as the plant has them, and written
    in the JSON as a discovered entry with its terms in SI units."""
    truth, result, s, folder = suite["other_boom_bending"]
    assert [r.name for r in result.chosen] == ["discovered_z_ringing"], result.verdict
    found = result.chosen[0].candidate.discovery
    plant = _effect(truth)
    assert abs(found.frequency - plant["freq_hz"]) <= 0.05 * plant["freq_hz"], found.frequency
    decay = plant["zeta"] * 2 * 3.141592653589793 * plant["freq_hz"]
    assert abs(found.decay - decay) <= 0.3 * decay, (found.decay, decay)
    amplitude = found.amplitude * result.chosen[0].value
    assert abs(amplitude - plant["amplitude"]) <= 0.2 * plant["amplitude"], amplitude
    doc = json.loads((folder / "other_boom_bending.verdict.json").read_text())
    entry = doc["verdict"][0]
    assert entry["kind"] == "discovered" and [t["unit"] for t in entry["terms"]] == ["m", "m"], entry
    assert "rings" in entry["words"] and result.after.E_p <= result.before.E_p * 1.01


@pytest.fixture(scope="module")
def residuals(tmp_path_factory):
    """The located residuals of two recordings whose law no library entry has, under the model."""
    from hopper_ros.diagnosis.core import base_variant
    from hopper_ros.diagnosis.data import prepare
    from hopper_ros.diagnosis.settings import load_settings
    from hopper_ros.diagnosis.locate import residual_sets
    from hopper_ros.recording.recordings import load_recording
    from hopper_ros.physics.params import load_model

    folder = tmp_path_factory.mktemp("laws")
    names = ("other_hip_torsion_spring", "other_bump_stop")
    stored_recordings.independent(folder, names)
    params, effects = load_model("model.yaml")
    settings = load_settings("diagnosis.yaml")
    out = {}
    for name in names:
        data = prepare(load_recording(folder / f"{name}.csv"), params, settings.min_strides, settings.liftoff_window)
        out[name] = (json.loads((folder / f"{name}.json").read_text()), residual_sets(data, base_variant(params, effects)))
    return out


def test_discovery_picks_the_one_term_that_stands_for_two(residuals):
    """A torsional spring at the hip, tau = -kappa theta: theta = (theta - theta_td) + theta_td, so a constant and
    the swing since touchdown fit it too, and in stance sign(theta') is a constant as well (the leg sweeps one
    way). Best-subset selection over strides finds the single term, with the plant's stiffness."""
    from hopper_ros.diagnosis.discover import discover_site

    truth, sets = residuals["other_hip_torsion_spring"]
    found = discover_site("stance_hip", sets)
    terms = {key: coef for key, coef, _, _ in found.terms()}
    assert set(terms) == {"theta"}, terms
    kappa = truth["effects"][0]["magnitude"]
    assert abs(-terms["theta"] - kappa) <= 0.3 * kappa, terms


def test_a_stop_the_leg_reaches_is_a_hinge_at_its_compression(residuals):
    """A bump stop engaging 25 mm into the stroke: the knot is chosen by held-out strides among the compressions
    the recording reaches, near the plant's."""
    from hopper_ros.diagnosis.discover import discover_site

    truth, sets = residuals["other_bump_stop"]
    found = discover_site("stance_along", sets)
    terms = {key: coef for key, coef, _, _ in found.terms()}
    assert "x>x_k" in terms and terms["x>x_k"] > 0, terms
    engage = _effect(truth)["engage_compression"]
    assert abs(found.knot - engage) <= 0.2 * engage, found.knot


def test_a_mismatch_no_force_shows_is_located_by_trajectory(tmp_path):
    """A toe that slips under large hip torques: under the model alone the force residuals stay within the noise
    one stride at a time, but the re-simulated strides miss the recording by tens of noise levels; locate by
    trajectory finds where they first leave it, in stance (what the tool says where no law it has fits). (With
    the library's toe slip the strides return to the recording: named, mu within 20 % of the plant's, in `make
    bench`'s diagnosis of the whole suite: a diagnosis of 40 s.)"""
    from hopper_ros.diagnosis.core import base_variant
    from hopper_ros.diagnosis.data import prepare
    from hopper_ros.diagnosis.locate import locate
    from hopper_ros.diagnosis.simulate import simulate_variants
    from hopper_ros.diagnosis.yardstick import locate_by_trajectory, start_moves
    from hopper_ros.physics.params import load_model
    from hopper_ros.recording.recordings import load_recording

    stored_recordings.independent(tmp_path, ("other_toe_slip",))
    folder, settings = tmp_path, Settings()
    params, effects = load_model("model.yaml")
    data = prepare(load_recording(folder / "other_toe_slip.csv"), params, settings.min_strides, settings.liftoff_window)
    base = base_variant(params, effects)
    assert all(loc.ratio < settings.locate_threshold for loc in locate(data, base)[0])
    sim = simulate_variants(data, [base], keep_series=True)
    first = locate_by_trajectory(data, sim["series"], start_moves(data, base, sim), settings)
    assert first is not None and first.basis == "trajectory" and first.site in ("stance_hip", "stance_along")
    assert "compression" in first.window, first.words()


def test_identify_then_diagnose_closes_the_researchers_loop(hopper_cli, tmp_path):
    """Issue 28's loop: a hip that delivers 0.75 of the commanded torque, the angle quantised only (as an
    incremental encoder gives it, no white noise). `identify --effects torque_gain` finds the gain, and
    `diagnose --model` with the model it wrote finds nothing left: the tool does not flag what the
    researcher already modelled (it said "something unmodelled ... 45 x the noise level" once)."""
    from independent_plant import effects as fx
    from independent_plant.runner import NoiseSpec, write_csv
    from independent_plant.suite import Spec, make_recording

    columns, truth, _ = make_recording(Spec("gain_quantised", lambda: [fx.ActuatorGain(0.75)]),
                                       noise=NoiseSpec(y_std=0.0, z_std=0.0, theta_std=0.0))
    recording = tmp_path / "gain_quantised.csv"
    write_csv(recording, *columns)
    identified = tmp_path / "identified"
    run = hopper_cli("identify", str(recording), "--effects", "torque_gain", "-o", str(identified), "--no-progress")
    assert run.wait(150) == 0, run.stderr
    model = identified / "identified_model.yaml"
    from hopper_ros.physics.params import load_model

    assert abs(load_model(model)[1]["torque_gain"] - 0.75) < 0.01
    verdict = tmp_path / "verdict.json"
    diagnosed = hopper_cli("diagnose", str(recording), "--model", str(model), "--json", str(verdict))
    assert diagnosed.wait(150) == 0, diagnosed.stderr
    result = json.loads(verdict.read_text())
    assert "no significant mismatch" in diagnosed.stdout, diagnosed.stdout
    assert result["verdict"] == [] and not any(site["above_noise"] for site in result["location"]), result["summary"]
