"""The MuJoCo plant (test/mujoco_plant): its self-checks and a short suite in plant C's format."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent / "mujoco_plant"
pytestmark = pytest.mark.compute   # CPU-bound (the engine's runs): `make test` runs these beside the node tests

try:
    import mujoco  # noqa: F401
except ImportError as exc:  # pragma: no cover - make setup installs it (requirements/test.txt)
    pytest.skip(f"mujoco cannot be imported ({exc}); `make setup` installs it",
                allow_module_level=True)


def test_self_checks():
    r = subprocess.run([sys.executable, str(HERE / "check.py")], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "all checks passed" in r.stdout


def test_short_suite_writes_plant_c_format(tmp_path):
    names = ["mj_clean", "mj_default"]
    r = subprocess.run([sys.executable, str(HERE / "suite.py"), "--strides", "3", str(tmp_path),
                        *names], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    for name in names:
        lines = (tmp_path / f"{name}.csv").read_text().splitlines()
        assert lines[0] == "t,y,z,theta,tau"
        data = np.loadtxt(tmp_path / f"{name}.csv", delimiter=",", skiprows=1)
        steps = np.diff(data[:, 0])
        assert (np.isclose(steps, 1e-3, atol=1e-6) | (steps >= 1.0)).all()
        assert (data[:, 4] <= 0).all() and (data[:, 4] < 0).any()
        truth = json.loads((tmp_path / f"{name}.json").read_text())
        assert truth["name"] == name and truth["strides"] == 3
        ids = {e["id"] for e in truth["effects"]}
        assert {"soft_contact", "toe_mass_in_flight"} <= ids
        if name == "mj_default":
            assert {"leg_inertia", "hip_rotor_inertia", "boom_hinges"} <= ids
