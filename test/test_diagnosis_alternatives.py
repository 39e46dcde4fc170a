"""Laws of the same part told apart from an accepted library look-alike (issue 28, point 1: the size of the commanded
torque; hopper_ros/diagnosis/alternatives.py): a torque dead band of plant B (test/plant_b/, written blind) with a
size and seed of its own (not its suite's case) is named as a dead band, where the library's nearest law is a dry
friction of the hip, and a torque that falls with the leg's sweep as a torque-speed line, not a gain; the
independent plant's real dry hip friction, torque gain and flight-only boom friction keep their names; plant B's
cable pulling back in every phase is a friction of the boom's bearing in stance too, not the flight's alone; a
softening spring of plant B (a diagnosis of minutes: `long`). The laws themselves: a command inside the dead band
gives no torque, the torque-speed line, the spring's quadratic term, the bearing's friction in stance."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from hopper_ros.diagnosis import diagnose_file
from hopper_ros.physics import laws

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
import stored_recordings  # noqa: E402

DEAD_BAND = 0.35                 # [N m] plant B's tau_db (its suite has 0.27 and 0.21)
SEED = 4217


def plant_b_recording(folder: Path, name: str, effect: str, seed: int) -> Path:
    """A recording of plant B (its own simulate and writer, in a process of its own) with the one effect `effect`
    (an expression of its effects module, `E`); its CSV's path."""
    return stored_recordings.plant_b(folder, f"""
        import sys
        from plant_b import effects as E
        from plant_b.suite import simulate, write
        effs = [{effect}]
        out, strides, summary, _ = simulate("{name}", effs, {seed})
        write(sys.argv[1], "{name}", effs, {seed}, out, strides, summary)
        """) / f"{name}.csv"


@pytest.fixture(scope="module")
def dead_band(tmp_path_factory):
    path = plant_b_recording(tmp_path_factory.mktemp("dead_band"), "dead_band", f"E.TorqueDeadband({DEAD_BAND})", SEED)
    return diagnose_file(path, json_path=path.with_suffix(".diagnosis.json")), path


def test_a_command_inside_the_dead_band_gives_no_torque_and_a_larger_one_loses_the_band():
    c = laws.Coefficients(torque_dead_band=0.3)
    assert laws.actuator_torque(c, np.array([-2.0, -0.2, 0.0, 0.25, 1.0])) == pytest.approx([-1.7, 0.0, 0.0, 0.0, 0.7])
    assert laws.actuator_torque(laws.Coefficients(), 0.25) == pytest.approx(0.25)      # off: the command itself


def test_the_torque_falls_linearly_with_the_sweep_to_none_at_the_no_load_sweep():
    c = laws.Coefficients(torque_speed_slope=0.01)
    assert laws.speed_derated(c, 5.0, np.array([0.0, -20.0, 50.0, 150.0])) == pytest.approx([5.0, 4.0, 2.5, 0.0])


def test_the_spring_quadratic_term_adds_k2_times_the_compression_squared():
    plain = laws.Coefficients()
    softening = plain.replace(spring_quadratic=-9000.0)
    rho = plain.rest_length - 0.04
    assert laws.leg_force(softening, rho, 0.0) - laws.leg_force(plain, rho, 0.0) == pytest.approx(-9000.0 * 0.04 ** 2)


def test_the_bearing_friction_in_stance_brakes_the_forward_motion_only():
    plain = laws.Coefficients()
    braked = plain.replace(stance_friction_y=0.2)
    state = (0.0, 0.19, 1.2, -0.4, 0.0, -0.03)      # y, z, y', z', ground depth, toe y [m, m/s]
    off, on = laws.stance_forces(plain, *state, 1.0), laws.stance_forces(braked, *state, 1.0)
    assert on.ydd - off.ydd == pytest.approx(-0.2, rel=1e-3) and on.zdd == pytest.approx(off.zdd)


@pytest.mark.compute
def test_a_torque_dead_band_is_named_as_one_not_as_the_hips_dry_friction(dead_band):
    """The dry friction fits most of it (both take torque while the ramp is above the band); the dead band gives
    nothing once the ramp falls below it and after the ramp, where a friction still brakes the sweep: held-out
    strides tell them apart. The dry friction stays as its look-alike, in words and in --json."""
    result, path = dead_band
    names = [r.name for r in result.chosen]
    assert names == ["torque_dead_band"], result.verdict
    assert result.chosen[0].magnitude == pytest.approx(DEAD_BAND, rel=0.2), result.verdict
    assert "hip_dry_friction" in [r.name for r in result.chosen[0].ties], result.verdict
    written = json.dumps(json.loads(path.with_suffix(".diagnosis.json").read_text()))
    assert "torque_dead_band" in written and "a dead band" in written


@pytest.mark.compute
@pytest.mark.parametrize("recording, effect, law", [
    ("hip_friction_coulomb", "hip_dry_friction", "torque_dead_band"),
    # make test's budget: these two (20 s each) are in `make bench` (bench/bench_long_tests.py), whose diagnosis of the
    # whole independent suite (bench/diagnosis_suite.py) names them too
    pytest.param("actuator_gain", "torque_gain", "torque_speed_slope", marks=pytest.mark.long),
    pytest.param("flight_boom_coulomb", "boom_friction_horizontal", "boom_bearing_friction", marks=pytest.mark.long)])
def test_a_real_library_effect_keeps_its_name(tmp_path, recording, effect, law):
    """The independent plant's Coulomb friction in the hip gearbox (0.4 N m), its torque gain (0.85), its boom
    bearing's friction while airborne (0.15 m/s^2, flight only): the law of the same part is tried in its place and
    does not win."""
    stored_recordings.independent(tmp_path, (recording,))
    result = diagnose_file(tmp_path / f"{recording}.csv")
    names = [r.name for r in result.chosen]
    assert effect in names and law not in names, result.verdict


@pytest.mark.compute
@pytest.mark.long     # a diagnosis of 50 s CPU: `make bench` runs it (bench/bench_long_tests.py)
def test_a_torque_that_falls_with_the_sweep_is_a_torque_speed_line_not_a_gain(tmp_path):
    """Plant B's voltage-limited motor, tau = tau_cmd max(0, 1 - |theta'|/w0), with a size and seed of its own: a
    lower gain fits most of it; the torque-speed line replaces it, with the plant's no-load sweep within 20 %."""
    no_load = 110.0      # [rad/s] plant B's w0 (its suite has 137)
    result = diagnose_file(plant_b_recording(tmp_path, "speed", f"E.BackEMF({no_load})", SEED + 2))
    assert [r.name for r in result.chosen] == ["torque_speed_slope"], result.verdict
    assert 1.0 / result.chosen[0].magnitude == pytest.approx(no_load, rel=0.2), result.verdict
    assert "torque_gain" in [r.name for r in result.chosen[0].ties], result.verdict


@pytest.mark.compute
def test_a_pull_in_every_phase_is_the_bearings_friction_in_stance_too_not_the_flights_alone(tmp_path):
    """Plant B's power cable dragged behind the robot, a constant backward force in every phase, with a size and
    seed of its own: the flight-only boom friction fits the flights and overshoots to make up the stances; the
    friction in every phase replaces it, with the plant's pull within 10 % (a m_b, m_b = 2.2 kg), and the flight's
    stays as its look-alike."""
    pull = 0.3       # [N] plant B's F (its suite has 0.21)
    result = diagnose_file(plant_b_recording(tmp_path, "tether", f"E.TetherPull({pull})", SEED + 3))
    assert [r.name for r in result.chosen] == ["boom_bearing_friction"], result.verdict
    assert 2.2 * result.chosen[0].magnitude == pytest.approx(pull, rel=0.1), result.verdict
    assert "boom_friction_horizontal" in [r.name for r in result.chosen[0].ties], result.verdict


@pytest.mark.compute
@pytest.mark.long     # a diagnosis of minutes (discovery at the leg): `make bench` runs it (bench/bench_long_tests.py)
def test_a_spring_that_softens_is_its_quadratic_term_not_a_softer_leg_with_patches(tmp_path):
    """Plant B's softening spring, F = k x - k2 x^2, with a size and seed of its own: the rounds end with a softer
    leg and discovered terms along the leg beside it; the spring's quadratic term replaces both, with the plant's
    k2 within 20 %, and the softer leg stays as its look-alike."""
    k2 = 10000.0
    result = diagnose_file(plant_b_recording(tmp_path, "softening", f"E.SofteningSpring({k2})", SEED + 1))
    assert [r.name for r in result.chosen] == ["spring_quadratic"], result.verdict
    assert result.chosen[0].magnitude == pytest.approx(-k2, rel=0.2), result.verdict
    assert "leg_stiffness" in [r.name for r in result.chosen[0].ties], result.verdict
