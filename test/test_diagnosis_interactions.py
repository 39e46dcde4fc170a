"""Laws that are products of two of the model's variables (issue 28, point 3), on the independent plant
(test/independent_plant/: its own integrator and stance, nothing of ours) with a mechanism written here in its
own effect interface: leg damping that grows with the compression, F += -c x rho' (an air or oil damper whose
orifice closes as the leg shortens). Without the product term the tool named a larger constant damping."""

import pytest

from hopper_ros.diagnosis import diagnose_file

from independent_plant.plant import Effect
from independent_plant.runner import write_csv
from independent_plant.suite import Spec, make_recording


class ProgressiveDamping(Effect):
    id, family, site, direction = "progressive_damping", "stance_leg", "stance_along_leg", "along"
    parameter, unit = "c", "N s/m^2"
    equation = "stance: F_leg += -c (rho_0 - rho) rho'"
    words = "The leg's damping grows with its compression."
    acts_in = ("stance",)

    def stance_along(self, c, model):
        return -self.magnitude * (model.rho_0 - c.rho) * c.rhodot


@pytest.fixture(scope="module")
def progressive(tmp_path_factory):
    folder = tmp_path_factory.mktemp("interactions")
    cols, truth, _ = make_recording(Spec("progressive_damping", lambda: [ProgressiveDamping(400.0)]))
    write_csv(folder / "progressive_damping.csv", *cols)
    return diagnose_file(folder / "progressive_damping.csv")


def test_damping_that_grows_with_compression_is_said_as_such(progressive):
    """Discovered along the leg with the compression x extension-rate term, its coefficient within 25 % of the
    plant's (400 N s/m^2), and the held-out next apexes improve."""
    result = progressive
    found = [r for r in result.chosen if r.candidate.kind == "discovered" and r.candidate.site == "stance_along"]
    assert found, result.verdict
    terms = {key: coef * found[0].value for key, coef, _, _ in found[0].candidate.discovery.terms()}
    assert "x rho'" in terms and abs(terms["x rho'"] - 400.0) <= 0.25 * 400.0, result.verdict
    assert "damping that grows with the compression" in result.verdict
    assert result.after.total < result.before.total
