"""Laws of what the model does not use (`diagnosis.unused`, issue 28 point 1): hysteresis in the leg force (a Bouc-Wen
element, `laws.hysteresis_rate`) and the forward position read with an error periodic in the boom's angle
(`simulate.periodic_y`, its period found by a frequency scan), the leg's swing in flight reacting on the body
(`swing`), the drive's voltage limiting the hip motor's current against its back-EMF (`backemf`), air leaking from
the leg (`relaxation`), the flight's
position servo released late after touchdown (`servo`), a round toe rolling in stance (`foot`,
`laws.stance_forces`), the body carried on the boom's sphere (`sphere`, `laws.boom_sphere`). Real diagnoses of short
recordings (28 strides) of plant C (test/plant_c/, written blind) made with its own generator at sizes and seeds the
suite does not use."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import stored_recordings
from hopper_ros.diagnosis import diagnose_file
from hopper_ros.diagnosis.simulate import periodic_y
from hopper_ros.physics import laws

pytestmark = pytest.mark.compute   # CPU-bound: `make test` runs these beside the node tests (tools/test.sh)

STRIDES = 28
HYSTERESIS = (2000.0, 0.0025)            # plant C's k_h [N/m], x_y [m]: a bound of 5 N
LAP = 2 * math.pi * (1.65 + 0.09)
ECCENTRICITY = (0.004, LAP / 4, 0.3)     # e [m], period [m] (four times a lap), phase
SWING = (0.4, 0.08)                      # plant C's leg mass m_l [kg], its centre below the hip r_c [m]
BACK_EMF = (8.0, 0.45)                   # plant C's drive voltage V [V], winding resistance R [ohm]
SERVO = (12.0, 0.03)                     # plant C's flight servo K_p [N m/rad], released t_h [s] after touchdown
FOOT = 0.02                              # plant C's round toe's radius r_f [m]
SPHERE = 1.3                             # plant C's boom radius R [m] (its pivot at hardware.yaml's 0.115 m)
PAIR = (0.022, 8.5, 0.5)                 # a round toe r_f [m] and the drive's voltage limit V [V] over R [ohm] at once
AIR = (5e-4, 6.5e-5, 0.045)              # plant C's air chamber: piston area A [m^2], volume V0 [m^3], leak tau_l [s]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("unused")
    stored_recordings.plant_c(folder, f"""
        import sys
        from pathlib import Path
        from effects import make
        from suite import simulate, write
        k_h, x_y = {HYSTERESIS!r}
        e, period, phi = {ECCENTRICITY!r}
        for name, mechanism, seed in (("hysteresis", make("spring_hysteresis", k_h=k_h, x_y=x_y), 4101),
                                      ("eccentricity", make("azimuth_eccentricity", e=e, P=period, phi=phi), 4102),
                                      ("swing", make("leg_swing_reaction", m_l={SWING[0]}, r_c={SWING[1]}), 4103),
                                      ("back_emf", make("motor_back_emf", V={BACK_EMF[0]}, R={BACK_EMF[1]}), 4104),
                                      ("servo", make("servo_handoff", K_p={SERVO[0]}, t_h={SERVO[1]}), 4106),
                                      ("foot", make("round_foot", r_f={FOOT}), 4105),
                                      ("sphere", make("boom_centripetal", R={SPHERE}), 4107),
                                      ("air", make("air_chamber", A={AIR[0]}, V0={AIR[1]}, tau_l={AIR[2]}), 4109)):
            meas, truth, _ = simulate(name, [mechanism.id], seed, strides={STRIDES}, mechanisms=[mechanism])
            write(Path(sys.argv[1]), name, meas, truth)
        pair = [make("round_foot", r_f={PAIR[0]}), make("motor_back_emf", V={PAIR[1]}, R={PAIR[2]})]
        meas, truth, _ = simulate("pair", [m.id for m in pair], 4108, strides={STRIDES}, mechanisms=pair)
        write(Path(sys.argv[1]), "pair", meas, truth)
        """)
    return folder


def test_the_laws_turn_after_a_reversal_and_read_a_periodic_error():
    """Bouc-Wen: loading from rest q = 1 - exp(-x/x_y); after the reversal q falls linearly with the compression
    (elastic) until it changes sign. The periodic reading's slope is its derivative."""
    c = laws.Coefficients(leg_hysteresis=1.0, leg_hysteresis_yield=0.002)
    q, dx = 0.0, 1e-6
    for _ in range(10000):                                  # 10 mm of compression
        q += laws.hysteresis_rate(c, q, 1.0) * dx
    assert q == pytest.approx(1.0 - math.exp(-5.0), abs=1e-3)
    for _ in range(1000):                                   # 1 mm back
        q += laws.hysteresis_rate(c, q, -1.0) * dx
    assert q == pytest.approx(1.0 - math.exp(-5.0) - 0.5, abs=1e-3)
    y = np.linspace(0.0, 3.0, 7)
    error, slope = periodic_y(y, 0.003, -0.001, 1.8)
    assert error == pytest.approx(0.003 * np.sin(2 * np.pi * y / 1.8) - 0.001 * np.cos(2 * np.pi * y / 1.8))
    assert slope == pytest.approx((periodic_y(y + 1e-7, 0.003, -0.001, 1.8)[0] - error) / 1e-7, rel=1e-4, abs=1e-9)


def test_the_relaxing_leg_force_is_an_air_spring_that_leaks_and_a_maxwell_element_without_a_chamber():
    """Without a leak the force is the adiabatic gas's, p_a A ((L / (L - x))^1.4 - 1) with k_r = 1.4 p_a A / L; with
    1/L = 0 a compression at a constant rate v gives the Maxwell element's k_r v tau_r (1 - exp(-t / tau_r))."""
    area, length, p_a = 4e-4, 0.08, 101325.0
    stiffness = laws.AIR_ADIABATIC_INDEX * p_a * area / length
    c = laws.Coefficients(leg_relaxing_stiffness=stiffness, leg_relaxation_time=1e9,
                          leg_relaxation_curvature=1 / length)
    force, x, dx = 0.0, 0.0, 1e-6
    while x < 0.03 - 1e-12:                                 # 30 mm, RK2 in the compression
        half = force + 0.5 * dx * laws.relaxation_rate(c, force, x, 1.0)
        force += dx * laws.relaxation_rate(c, half, x + 0.5 * dx, 1.0)
        x += dx
    assert force == pytest.approx(p_a * area * ((length / (length - 0.03)) ** 1.4 - 1.0), rel=1e-6)
    c = laws.Coefficients(leg_relaxing_stiffness=600.0, leg_relaxation_time=0.02)
    force, dt, speed = 0.0, 1e-6, 0.5
    for _ in range(40000):                                  # 40 ms at 0.5 m/s
        half = force + 0.5 * dt * laws.relaxation_rate(c, force, 0.0, speed)
        force += dt * laws.relaxation_rate(c, half, 0.0, speed)
    assert force == pytest.approx(600.0 * speed * 0.02 * (1.0 - math.exp(-2.0)), rel=1e-6)


def test_hysteresis_in_the_leg_force_is_named_by_its_bound_not_a_dry_friction(recordings):
    """Plant C's Bouc-Wen leg force of +-5 N (k_h x_y): named `leg_hysteresis` within 25 %, in words and --json,
    not the library's dry friction along the leg (its look-alike) nor by no law at all."""
    path = recordings / "hysteresis.csv"
    result = diagnose_file(path, json_path=path.with_suffix(".diagnosis.json"))
    names = [r.name for r in result.chosen]
    assert names == ["leg_hysteresis"], result.verdict
    want = HYSTERESIS[0] * HYSTERESIS[1]
    assert abs(result.chosen[0].magnitude - want) <= 0.25 * want, result.verdict
    assert "hysteresis in the leg force" in result.verdict, result.verdict
    entry = next(e for e in json.loads(path.with_suffix(".diagnosis.json").read_text())["verdict"]
                 if e["name"] == "leg_hysteresis")
    assert entry["unit"] == "N" and entry["magnitude"] == pytest.approx(result.chosen[0].magnitude)
    assert "Bouc-Wen" in entry["words"]


@pytest.mark.long     # a diagnosis of 50 s CPU, every stage searched: `make bench` runs it (bench/bench_long_tests.py)
def test_air_that_leaks_from_the_leg_is_named_a_relaxing_force_not_a_preload_or_a_stiffer_spring(recordings):
    """Plant C's air chamber at a size and leak the suite does not use (L = V0/A = 130 mm, 45 ms: neither on the
    search's grid): named `leg_relaxation` alone, an air spring that leaks, and explained; before the pattern search
    a preload stood in beside it (its late pull), before the law discovered terms or a cubic spring. Its size is not
    asserted: 706 N/m for 546 (+29 %, the chamber found nearly linear; docs/diagnosis_measured.md)."""
    result = diagnose_file(recordings / "air.csv")
    assert [r.name for r in result.chosen] == ["leg_relaxation"], result.verdict
    assert "an air spring that leaks" in result.verdict and "explained" in result.verdict, result.verdict


def test_a_reading_periodic_in_the_boom_angle_is_found_by_the_frequency_scan(recordings):
    """Plant C's azimuth encoder eccentric by 4 mm, four times a lap: the scan over the forward position finds the
    period within 10 % and the amplitude within 25 %, said as a harmonic of the lap."""
    result = diagnose_file(recordings / "eccentricity.csv")
    names = [r.name for r in result.chosen]
    assert names == ["y_periodic"], result.verdict
    found = result.chosen[0]
    assert abs(found.candidate.discovery.period - ECCENTRICITY[1]) <= 0.1 * ECCENTRICITY[1], result.verdict
    assert abs(found.magnitude - ECCENTRICITY[0]) <= 0.25 * ECCENTRICITY[0], result.verdict
    assert "periodic in the boom's angle" in result.verdict and "4 times a lap" in result.verdict, result.verdict


def test_the_legs_swing_in_flight_is_the_bodys_recoil_about_the_centre_of_mass(recordings):
    """Plant C's leg of 0.4 kg, its centre 8 cm below the hip, swung in flight: the model re-simulated as the centre of
    mass of body and leg (`leg_swing` at the plant's mu r_c) brings the next apexes to within a third of the model's
    errors (the apex speed read at the apex is the body's, off by the swing's recoil), and does better than half or
    twice the size. No diagnosis: the law alone (a few seconds)."""
    from hopper_ros.diagnosis.core import start
    from hopper_ros.diagnosis.records import Errors
    from hopper_ros.diagnosis.settings import load_settings
    from hopper_ros.diagnosis.simulate import simulate_variants
    from hopper_ros.physics.params import load_model
    from hopper_ros.recording.recordings import load_recording

    assert laws.swing_offset(0.3, 0.3) == (0.0, 0.0)
    dy, dz = laws.swing_offset(0.4, -0.4)
    assert dy == pytest.approx(2 * math.sin(0.4)) and dz == pytest.approx(0.0, abs=1e-12)
    params, effects = load_model("model.yaml")
    search, _, model = start(load_recording(recordings / "swing.csv"), params, load_settings("diagnosis.yaml"), effects)
    mu_rc = SWING[0] / (2.2 + SWING[0]) * SWING[1]
    sizes = (0.5 * mu_rc, mu_rc, 2.0 * mu_rc)
    sim = simulate_variants(search.data, [search.base.with_changes(sensors={"leg_swing": v}) for v in sizes])
    errors = [Errors.of(search.data, {k: v[row] for k, v in sim["pred"].items()}).total for row in range(3)]
    assert errors[1] < model.errors.total / 3, (errors, model.errors)
    assert errors[1] < min(errors[0], errors[2]), errors


def test_the_drives_voltage_limit_falls_with_the_legs_sweep():
    """`laws.voltage_limited`: a torque within k V/R - (k^2/R) theta' passes, one beyond is clipped to that line
    (less is left the faster the leg sweeps the way the motor drives), and a lane without a voltage is not limited."""
    import numpy as np
    c = laws.Coefficients(drive_voltage=np.array([9.0, 9.0, 9.0, 0.0]), winding_resistance=0.6, motor_constant=0.627)
    torque = np.array([-3.0, -12.0, -12.0, -12.0])
    sweep = np.array([-8.0, 0.0, -8.0, -8.0])                 # [rad/s] the leg sweeping back in stance
    limited = laws.voltage_limited(c, torque, sweep)
    stall, electrical = 0.627 * 9.0 / 0.6, 0.627 ** 2 / 0.6
    assert limited == pytest.approx([-3.0, -stall, -stall + 8.0 * electrical, -12.0])


def test_a_hip_torque_limited_by_the_drives_voltage_is_the_back_emf_not_a_saturation(recordings):
    """Plant C's hip motor behind a drive of 8 V over 0.45 ohm: the model with the voltage limit at the plant's size
    (`drive_voltage`) brings the next apexes to within a third of the model's errors and does better than half or twice
    the voltage; a fixed saturation at the stall torque does not. No diagnosis: the law alone (a few seconds)."""
    from hopper_ros.diagnosis import backemf
    from hopper_ros.diagnosis.core import start
    from hopper_ros.diagnosis.records import Errors
    from hopper_ros.diagnosis.settings import load_settings
    from hopper_ros.diagnosis.simulate import simulate_variants
    from hopper_ros.physics.params import load_model
    from hopper_ros.recording.recordings import load_recording

    params, effects = load_model("model.yaml")
    search, _, model = start(load_recording(recordings / "back_emf.csv"), params, load_settings("diagnosis.yaml"),
                             effects)
    voltage, resistance = BACK_EMF
    k = backemf.motor_constant()
    variants = [search.base.with_changes(coefficients={"drive_voltage": v, "winding_resistance": resistance,
                                                       "motor_constant": k})
                for v in (0.5 * voltage, voltage, 2 * voltage)]
    variants.append(search.base.with_changes(coefficients={"torque_limit": k * voltage / resistance}))
    sim = simulate_variants(search.data, variants)
    errors = [Errors.of(search.data, {key: v[row] for key, v in sim["pred"].items()}).total for row in range(4)]
    assert errors[1] < model.errors.total / 3, (errors, model.errors)
    assert errors[1] < min(errors[0], errors[2], errors[3]), errors


def test_a_servo_released_late_pulls_the_leg_back_early_in_stance_only(recordings):
    """Plant C's flight servo of 12 N m/rad released 30 ms after touchdown: the model with the servo's pull at the
    plant's size (`servo_release`) brings the next apexes to within a third of the model's errors, and does better
    than half or twice the stiffness and than the same pull over the whole stance (a centring spring) or released at
    half the time. No diagnosis: the law alone (a few seconds)."""
    from hopper_ros.diagnosis.core import start
    from hopper_ros.diagnosis.records import Errors
    from hopper_ros.diagnosis.settings import load_settings
    from hopper_ros.diagnosis.simulate import simulate_variants
    from hopper_ros.physics.params import load_model
    from hopper_ros.recording.recordings import load_recording

    c = laws.Coefficients(servo_stiffness=10.0, servo_release=0.02)
    assert laws.servo_hold(c, np.array([0.1, 0.1, 0.1]), 0.2, np.array([-0.001, 0.01, 0.03])) == pytest.approx(
        [0.0, 1.0, 0.0])
    params, effects = load_model("model.yaml")
    search, _, model = start(load_recording(recordings / "servo.csv"), params, load_settings("diagnosis.yaml"), effects)
    stiffness, release = SERVO
    sizes = [(0.5 * stiffness, release), (stiffness, release), (2 * stiffness, release), (stiffness, 1.0),
             (stiffness, 0.5 * release)]
    sim = simulate_variants(search.data, [search.base.with_changes(
        coefficients={"servo_stiffness": k, "servo_release": t}) for k, t in sizes])
    errors = [Errors.of(search.data, {key: v[row] for key, v in sim["pred"].items()}).total
              for row in range(len(sizes))]
    assert errors[1] < model.errors.total / 3, (errors, model.errors)
    assert errors[1] < min(errors[:1] + errors[2:]), errors


def test_a_round_toe_rolls_its_contact_point_forward_and_lands_at_a_height_even_in_the_leg_angle(recordings):
    """Plant C's toe a ball of 2 cm rolling in stance: the model re-simulated with the rolling contact
    (`foot_radius` at the plant's r_f: the contact point moving r_f per radian, the touchdown r_f (1 - cos theta)
    higher, the leg force acting from the contact point) brings the next apexes to within a tenth of the model's
    errors (a twenty-fifth here: E_p + E_v + E_t 8.81 -> 0.33 %) and does better than half or twice the size. The
    touchdown height is even in the leg angle (an angle offset's is not). No diagnosis: the law alone (a second)."""
    from hopper_ros.diagnosis.core import start
    from hopper_ros.diagnosis.records import Errors
    from hopper_ros.diagnosis.settings import load_settings
    from hopper_ros.diagnosis.simulate import simulate_variants
    from hopper_ros.physics.params import load_model
    from hopper_ros.recording.recordings import load_recording

    c = laws.Coefficients(foot_radius=FOOT)
    assert laws.touchdown_height(c, 0.3) == pytest.approx(laws.touchdown_height(c, -0.3))
    assert laws.touchdown_height(c, 0.3) == pytest.approx((c.rest_length - FOOT) * math.cos(0.3) + FOOT)
    assert laws.touchdown_height(c, 0.0) == laws.touchdown_height(laws.Coefficients(), 0.0)
    params, effects = load_model("model.yaml")
    search, _, model = start(load_recording(recordings / "foot.csv"), params, load_settings("diagnosis.yaml"), effects)
    sizes = (0.5 * FOOT, FOOT, 2.0 * FOOT)
    sim = simulate_variants(search.data, [search.base.with_changes(coefficients={"foot_radius": v}) for v in sizes])
    errors = [Errors.of(search.data, {k: v[row] for k, v in sim["pred"].items()}).total for row in range(3)]
    assert errors[1] < model.errors.total / 10, (errors, model.errors)
    assert errors[1] < min(errors[0], errors[2]), errors


def test_the_body_on_the_booms_sphere_is_named_by_its_radius(recordings):
    """Plant C's boom of 1.3 m: its forward speed pulls the raised body down and pushes it along the track (the
    sphere's centripetal and Coriolis terms, its height read along the arc). Named `boom_curvature` by its radius
    within 25 %, the reading said, in words and --json."""
    result = diagnose_file(recordings / "sphere.csv", json_path=recordings / "sphere_diagnosis.json")
    named = {r.name: r for r in result.chosen}
    assert "boom_curvature" in named, result.verdict
    assert abs(named["boom_curvature"].magnitude - SPHERE) <= 0.25 * SPHERE, result.verdict
    assert "the boom's sphere, radius R" in result.verdict and "read along the arc" in result.verdict, result.verdict
    doc = json.loads((recordings / "sphere_diagnosis.json").read_text())
    assert "boom_curvature" in json.dumps(doc["verdict"]), doc["verdict"]


def test_two_laws_that_trade_against_each_other_are_refitted_together(recordings):
    """Plant C's round toe and its drive's voltage limit at once: fitted one beside the other, each stands in for part
    of the other (plant C's suite: 0.018 m and 11 V for 0.025 m and 9 V, the next apex at 15 x its noise floor).
    `refit_jointly`, started there (the toe 20 % small, the voltage 30 % high), moves both to within 10 % of the plant's,
    the held-out next apex to a third of where it started and to within 1.5 x the model's with the plant's values. No
    diagnosis: the two laws and the refit (seconds)."""
    from hopper_ros.diagnosis import backemf, foot
    from hopper_ros.diagnosis.core import start
    from hopper_ros.diagnosis.records import Errors, Fit, Scored
    from hopper_ros.diagnosis.search import refit_jointly
    from hopper_ros.diagnosis.settings import load_settings
    from hopper_ros.diagnosis.simulate import simulate_variants
    from hopper_ros.physics.params import load_model
    from hopper_ros.recording.recordings import load_recording

    radius, voltage, resistance = PAIR
    params, effects = load_model("model.yaml")
    search, _, _ = start(load_recording(recordings / "pair.csv"), params, load_settings("diagnosis.yaml"), effects)
    k = backemf.motor_constant()
    command = float(np.max(np.abs(search.data.strides.tau_0)))
    laws_found = [(foot.foot_candidate(), 0.8 * radius),
                  (backemf.back_emf_candidate(resistance, k, command, backemf.sweep_bound(search.data)),
                   1.3 * voltage * k / resistance)]        # the voltage law's search value: the torque left at rest
    folds = len(np.unique(search.fold))
    chosen = [Scored(c, Fit(value, [value] * folds, [], [], np.array([value])), c.physical(value),
                     np.zeros(len(search.fold)), Errors(0.0, 0.0, 0.0, 0)) for c, value in laws_found]
    truth = search.base
    for c, value in zip((c for c, _ in laws_found), (radius, voltage * k / resistance)):
        truth = c.build(truth, value)
    sim = simulate_variants(search.data, [truth])
    at_truth = Errors.of(search.data, {key: v[0] for key, v in sim["pred"].items()}).total
    before = search.held_out(chosen).errors.total
    assert refit_jointly(search, chosen)
    assert abs(chosen[0].magnitude - radius) <= 0.1 * radius, chosen[0].magnitude
    assert abs(chosen[1].magnitude - voltage) <= 0.1 * voltage, chosen[1].magnitude
    after = search.held_out(chosen).errors.total
    assert after < before / 3 and after < 1.5 * at_truth, (after, before, at_truth)
