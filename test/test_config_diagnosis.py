"""diagnosis.yaml through its schema (hopper_ros.diagnosis.settings.DIAGNOSIS, issue 30): the shipped file
reads as the Settings it declares, and a bad file given to `hopper diagnose --settings` ends the tool
with one line naming the file, `diagnosis.KEY` and what is wrong (before the recording is read)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
import yaml

from conftest import REPO
from hopper_ros.config import load_yaml
from hopper_ros.diagnosis.settings import Settings, load_settings


def test_the_shipped_file_is_its_settings():
    values = load_yaml("diagnosis.yaml")["diagnosis"]
    settings = load_settings()
    assert all(getattr(settings, key) == value for key, value in values.items())
    assert type(settings.min_t) is float and type(settings.folds) is int
    assert settings.secondary_grid == Settings().secondary_grid           # a key the file leaves out: its default


# (key, value, words the line must hold)
CASES = [
    ("folds", 1, "diagnosis.folds: must be >= 2, got 1"),
    ("grid", 7.5, "diagnosis.grid: must be an integer (>= 2), got 7.5"),
    ("min_t", "three", "diagnosis.min_t: must be a number (>= 0), got 'three'"),
    ("liftoff_window", 0.0, "diagnosis.liftoff_window: must be > 0 s, got 0"),
    ("backlash_max", 0.0, "diagnosis.backlash_max: must be > 0 rad, got 0"),
    ("angle_scan", 1, "diagnosis.angle_scan: must be >= 2, got 1"),
    ("hysteresis_yield_min", 0.0, "diagnosis.hysteresis_yield_min: must be > 0 m, got 0"),
    ("min_tt", 3.0, "diagnosis.min_tt: unknown key; known here: folds, grid, min_strides"),
]


@pytest.mark.parametrize("key,value,words", CASES)
def test_a_bad_diagnosis_file_is_one_line(tmp_path, key, value, words):
    data = load_yaml("diagnosis.yaml")
    data["diagnosis"][key] = value
    bad = tmp_path / "diagnosis.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False))
    result = subprocess.run([sys.executable, "-m", "hopper_ros.cli", "diagnose", "missing.csv", "--settings", str(bad)],
                            capture_output=True, text=True, timeout=120, cwd=tmp_path,
                            env=dict(os.environ, PYTHONPATH=str(REPO)))
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 3 and len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert lines[0].startswith(f"hopper diagnose: error: {bad}: ") and words in lines[0], lines[0]
