"""The mismatch tool's acceptance rules (diagnosis/acceptance.py), each on its own: held-out statistics and
guards, the naming margins, the look-alike test, a real sensor's fault, the apex tolerance, a restarted set
replacing the accepted one. Synthetic held-out results; no simulation."""

from types import SimpleNamespace

import numpy as np
import pytest

from hopper_ros.diagnosis import acceptance
from hopper_ros.diagnosis.candidates import library_candidate
from hopper_ros.diagnosis.core import base_variant
from hopper_ros.diagnosis.records import Errors, Fit, Reference, Scored
from hopper_ros.diagnosis.settings import Settings
from hopper_ros.physics import effects as library
from hopper_ros.physics.params import load_params

SETTINGS = Settings()
STRIDES = 40
DATA = SimpleNamespace(sample_count=40 * 300, corr_length=10.0, model_sse=4000.0)
RNG = np.random.default_rng(7)
BASE_SSE = 100.0 * np.exp(RNG.normal(0.0, 0.2, STRIDES))
MODEL = Errors(1.0, 1.0, 1.0, 0)
REFERENCE = Reference(BASE_SSE, MODEL)
COEFFICIENTS = base_variant(load_params()).coefficients


def candidate(name):
    return library_candidate(library.get(name), COEFFICIENTS)


def scored(name="torque_gain", share=0.5, spread=0.02, errors=Errors(0.5, 0.5, 0.5, 0), magnitude=None,
           kind=None):
    """A candidate whose held-out SSE is `share` of the reference's per stride (log spread `spread`)."""
    c = candidate(name)
    if kind is not None:
        c = SimpleNamespace(**{**c.__dict__, "kind": kind})
    held = BASE_SSE * share * np.exp(RNG.normal(0.0, spread, STRIDES))
    r = Scored(c, Fit(0.0, [], [], [], np.zeros(0)), c.physical(c.origin) if magnitude is None else magnitude,
               held, errors)
    return acceptance.score(r, DATA, REFERENCE, SETTINGS)


def test_a_consistent_reduction_with_a_better_apex_passes():
    r = scored(share=0.5)
    assert r.significant and not r.rejected
    assert r.reduction == pytest.approx(0.5, abs=0.02) and r.t > 10
    assert r.total_reduction == pytest.approx((BASE_SSE.sum() - r.held_sse.sum()) / DATA.model_sse)


@pytest.mark.parametrize("kwargs, why", [
    ({"share": 0.95}, "held-out trajectory residual falls only"),
    ({"share": 0.8, "spread": 3.0}, "not consistent over strides"),
    ({"errors": Errors(1.02, 0.5, 0.5, 0)}, "held-out E_p worse"),
    ({"errors": Errors(0.99, 0.99, 0.99, 0)}, "the next apex is not predicted better"),
    ({"errors": Errors(0.5, 0.5, 0.5, 2)}, "2 more strides fall"),
])
def test_each_guard_rejects_with_its_reason(kwargs, why):
    r = scored(**kwargs)
    assert not r.significant and any(why in line for line in r.rejected), r.rejected


def test_the_apex_tolerance_and_its_slack():
    assert acceptance.worse_errors(Errors(1.01, 1.0, 1.0, 0), MODEL, 0.01) == []
    assert acceptance.worse_errors(Errors(1.0, 1.0, 1.0101, 0), MODEL, 0.01) == ["E_t"]
    assert acceptance.worse_errors(Errors(1.0, 1.0, 1.0100005, 0), MODEL, 0.01, slack=1e-6) == []


def test_a_sensor_fault_must_be_a_real_sensors():
    small = scored("z_delay", magnitude=0.0002)       # below what this data resolves
    real = scored("z_delay", magnitude=0.004)
    assert not acceptance.plausible(small) and not acceptance.real(small) and not small.significant
    assert any("not a fault a real sensor has" in line for line in small.rejected)
    assert acceptance.plausible(real) and acceptance.real(real) and real.significant
    # physics and discovered terms are real whatever their size, where the recording resolves it
    assert acceptance.real(scored("torque_gain", magnitude=123.0))
    # a sensor that leaves the next apex as it was must explain most of the residual
    partial = scored("z_delay", share=0.7, magnitude=0.004, errors=MODEL)
    assert not partial.significant and any("explains only" in line for line in partial.rejected)


def test_a_torque_limit_refitted_above_every_command_is_not_real():
    """A torque limit is searched where the commanded torques resolve it (0.3-1 x the largest); refitted beside
    other effects to 26 N m against commands up to 8.3 N m it clips nothing (plant B: said as a false verdict)."""
    c = library_candidate(library.get("torque_saturation"), COEFFICIENTS, {"command": 8.3})

    def limit(tau_max):
        value = c.origin if tau_max is None else 1.0 / tau_max         # searched as 1/tau_max
        return Scored(c, Fit(value, [], [], [], np.zeros(0)), c.physical(value), BASE_SSE, MODEL)

    assert acceptance.real(limit(6.0)) and acceptance.real(limit(8.3)) and acceptance.real(limit(3.0))
    assert not acceptance.real(limit(26.27)) and not acceptance.real(limit(None))


def test_a_sensor_fault_beats_physics_only_by_its_margin():
    physics = scored("torque_gain", share=0.5)
    close = scored("z_delay", share=0.48, magnitude=0.004)
    top, ties = acceptance.choose([physics, close], SETTINGS)
    assert top is physics and close.margin_only and not close.significant
    far = scored("z_delay", share=0.3, magnitude=0.004)
    physics = scored("torque_gain", share=0.5)
    top, _ = acceptance.choose([physics, far], SETTINGS)
    assert top is far


def test_discovered_terms_beat_the_library_only_by_their_margin():
    entry = scored("torque_gain", share=0.5)
    terms = scored("torque_offset", share=0.47, kind="discovered")
    top, ties = acceptance.choose([entry, terms], SETTINGS)
    assert top is entry and terms.margin_only and terms in ties
    assert acceptance.lost_on_a_margin([entry, terms]) == [terms]


def test_look_alikes_by_t_or_by_share():
    best = scored("torque_gain", share=0.5, spread=0.01)
    same = scored("torque_offset", share=0.5, spread=0.01)
    worse = Scored(same.candidate, same.fit, same.magnitude, best.held_sse * 1.3, same.errors)
    acceptance.score(worse, DATA, REFERENCE, SETTINGS)
    assert acceptance.not_worse(same, best, SETTINGS) and acceptance.look_alike(same, best, SETTINGS)
    assert not acceptance.not_worse(worse, best, SETTINGS)
    assert not acceptance.look_alike(worse, best, SETTINGS)
    # within tie_share of the best's reduction counts even when the t says worse
    nearly = Scored(same.candidate, same.fit, same.magnitude, best.held_sse * 1.001, same.errors, reduction=best.reduction)
    assert acceptance.look_alike(nearly, best, SETTINGS)
    top, ties = acceptance.choose([best, same, worse], SETTINGS)
    assert top in (best, same) and worse not in ties and len(ties) == 1


def test_paired_t_is_one_sided():
    a, b = np.array([2.0, 2.1, 1.9, 2.05]), np.array([1.0, 1.1, 0.9, 1.0])
    assert acceptance.paired_t(a, b) > 10
    assert acceptance.paired_t(b, a) < -10
    assert acceptance.paired_t(a, a) == 0.0
    assert acceptance.paired_t(a, a / 2) == np.inf          # the same ratio on every stride


def test_a_restarted_set_replaces_only_a_clearly_worse_one():
    best = Reference(BASE_SSE, Errors(0.5, 0.5, 0.5, 0))
    better = Reference(BASE_SSE * 0.7 * np.exp(RNG.normal(0.0, 0.02, STRIDES)), Errors(0.45, 0.5, 0.5, 0))
    assert acceptance.replaces(better, best, MODEL, SETTINGS)
    slightly = Reference(BASE_SSE * 0.95, better.errors)
    assert not acceptance.replaces(slightly, best, MODEL, SETTINGS)
    apex_worse = Reference(better.sse, Errors(0.6, 0.5, 0.5, 0))
    assert not acceptance.replaces(apex_worse, best, MODEL, SETTINGS)
    worse_than_model = Reference(better.sse, Errors(1.2, 0.1, 0.1, 0))
    assert not acceptance.replaces(worse_than_model, best, MODEL, SETTINGS)
    falls = Reference(better.sse, Errors(0.45, 0.5, 0.5, 1))
    assert not acceptance.replaces(falls, best, MODEL, SETTINGS)


def test_a_runner_up_must_fit_held_out_strides_consistently():
    assert acceptance.runner_up(scored(share=0.6), SETTINGS)
    assert not acceptance.runner_up(scored(share=0.95), SETTINGS)
    assert not acceptance.runner_up(scored(share=0.8, spread=3.0), SETTINGS)
