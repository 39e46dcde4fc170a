"""Parameter set: Table 4.1 defaults, YAML round trip, clear errors for non-physical values."""

import math

import pytest
import yaml

from hopper_ros.physics.params import ModelParams, load_params, save_params


def test_defaults_are_table_4_1():
    p = load_params()  # config/model.yaml
    assert p == ModelParams()
    assert (p.body_mass, p.toe_mass, p.gravity, p.stiffness, p.damping) == (2.20, 0.03, 11.42, 4696.0, 9.87)
    assert (p.flight_damping_horizontal, p.flight_damping_vertical, p.rest_length) == (0.01, 0.23, 0.205)
    assert p.collision_factor == pytest.approx(2.20 / 2.23)


def test_save_then_load_round_trips(tmp_path):
    p = ModelParams(stiffness=5100.0, damping=7.5, gravity=10.2)
    path = save_params(p, tmp_path / "identified.yaml", comment="identified from run 12")
    assert path.read_text().startswith("# identified from run 12")
    assert load_params(path) == p


@pytest.mark.parametrize("name, value, words", [
    ("body_mass", -2.2, "body_mass must be positive"),
    ("stiffness", 0.0, "stiffness must be positive"),
    ("toe_mass", -0.01, "toe_mass must not be negative"),
    ("damping", -1.0, "damping must not be negative"),
    ("flight_damping_vertical", -0.1, "flight_damping_vertical must not be negative"),
    ("gravity", math.nan, "gravity must be finite"),
    ("damping", 250.0, "damping ratio"),
])
def test_non_physical_values_are_rejected_by_name(name, value, words):
    with pytest.raises(ValueError, match=words):
        ModelParams(**{name: value})


def test_bad_files_name_the_file_and_the_key(tmp_path):
    good = ModelParams().as_dict()
    cases = {
        "unknown.yaml": {**good, "spring": 1.0},
        "missing.yaml": {k: v for k, v in good.items() if k != "damping"},
        "text.yaml": {**good, "stiffness": "stiff"},
        "negative.yaml": {**good, "body_mass": -1.0},
    }
    messages = {"unknown.yaml": "unknown parameter", "missing.yaml": "missing parameter",
                "text.yaml": "stiffness must be a number", "negative.yaml": "body_mass must be positive"}
    for name, data in cases.items():
        path = tmp_path / name
        path.write_text(yaml.safe_dump({"model": data}))
        with pytest.raises(ValueError, match=messages[name]) as info:
            load_params(path)
        assert name in str(info.value)
    broken = tmp_path / "broken.yaml"
    broken.write_text("model: [unclosed")
    with pytest.raises(ValueError, match="not valid YAML"):
        load_params(broken)
