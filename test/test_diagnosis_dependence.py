"""Dependence on the position along the track (issue 28, point 1; hopper_ros/diagnosis/dependence.py): a floor whose
height changes round the boom's lap, on recordings of two plants written blind (test/plant_b/, test/plant_c/) with
floors of sizes and places of their own (not their suites' cases), and clean recordings of three plants, on which
the stage, even when forced to run, says nothing."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

import stored_recordings
from hopper_ros.diagnosis import diagnose_file
from hopper_ros.diagnosis.core import base_variant
from hopper_ros.diagnosis.data import own_ramps, prepare
from hopper_ros.diagnosis.dependence import find_dependence, lap_length, track_position
from hopper_ros.diagnosis.settings import Settings
from hopper_ros.physics.params import load_params
from hopper_ros.recording.recordings import load_recording

pytestmark = pytest.mark.compute   # CPU-bound: `make test` runs these beside the node tests (tools/test.sh)

HERE = Path(__file__).resolve().parent
BOARD = {"H": 0.015, "y0": 5.0, "l": 3.0}             # plant C: a 15 mm board from 5 m over 3 m of each lap
WAVE = {"a": 0.012, "L": 10.9, "phase": 2.0}         # plant B: a 12 mm undulation once a lap
TILT = {"a": 0.012, "phi": 2.5}                      # plant C: a tilted pivot, the floor +-12 mm once a lap


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dependence")
    stored_recordings.plant_c(folder, f"""
        import sys
        from pathlib import Path
        from effects import make
        from suite import simulate, write
        meas, truth, _ = simulate("board", ["floor_board"], 4242, mechanisms=[make("floor_board", **{BOARD!r})])
        write(Path(sys.argv[1]), "board", meas, truth)
        meas, truth, _ = simulate("tilt", ["tilted_pivot"], 4343, mechanisms=[make("tilted_pivot", **{TILT!r})])
        write(Path(sys.argv[1]), "tilt", meas, truth)
        for name, seed in (("clean_a", 1001), ("clean_b", 1002)):
            meas, truth, _ = simulate(name, [], seed)
            write(Path(sys.argv[1]), "c_" + name, meas, truth)
        """)
    stored_recordings.plant_b(folder, f"""
        import sys
        from plant_b import effects as E
        from plant_b.suite import seed_of, simulate, write
        floor = [E.FloorUndulation({WAVE['a']}, {WAVE['L']}, {WAVE['phase']})]
        for name, effs in (("wave", floor), ("clean", [])):
            out, strides, summary, _ = simulate(name, effs, seed_of(name) + 7)
            write(sys.argv[1], "b_" + name, effs, seed_of(name) + 7, out, strides, summary)
        """)
    return stored_recordings.independent(folder, ["clean_1", "clean_2"])


def test_a_board_on_part_of_the_lap_is_said_with_its_height_and_place(recordings):
    """Strides that land on the board meet the floor 15 mm higher: the floor held level fits none of them; a
    board round the lap is found on held-out strides, its height within 25 % and its edges within 0.6 m, said in
    the verdict and in --json, and it takes most of the held-out next-apex error off."""
    path = recordings / "board.csv"
    result = diagnose_file(path, json_path=path.with_suffix(".diagnosis.json"))
    assert [d.form for d in result.dependences] == ["board"], result.verdict
    found = result.dependences[0]
    assert abs(found.magnitude - BOARD["H"]) <= 0.25 * BOARD["H"], found.sentence()
    start, end = found.where
    assert abs(start - BOARD["y0"]) <= 0.6 and abs(end - (BOARD["y0"] + BOARD["l"])) <= 0.6, found.sentence()
    assert "dependence: the floor is" in result.verdict and "mm higher over" in result.verdict, result.verdict
    assert found.after.total < 0.5 * found.before.total and found.t >= result.settings.min_t, found.sentence()
    entry = json.loads(path.with_suffix(".diagnosis.json").read_text())["dependence"][0]
    assert entry["form"] == "board" and entry["variable"] == "track position"
    assert entry["magnitude"] == pytest.approx(found.magnitude) and entry["unit"] == "m"


def test_an_undulating_floor_is_said_with_its_amplitude_and_crest(recordings):
    """A floor that rises and falls once a lap by +-12 mm (plant B's own law and lap): a wave of one period a lap
    is found by the scan over 1-3 periods, its amplitude within 25 % and its crest within 0.6 m of the plant's."""
    result = diagnose_file(recordings / "b_wave.csv")
    assert [d.form for d in result.dependences] == ["wave"], result.verdict
    found = result.dependences[0]
    periods, crest = found.where
    assert periods == 1 and abs(found.magnitude - WAVE["a"]) <= 0.25 * WAVE["a"], found.sentence()
    true_crest = (math.pi / 2 - WAVE["phase"]) / (2 * math.pi) * WAVE["L"] % found.lap
    assert min(abs(crest - true_crest), found.lap - abs(crest - true_crest)) <= 0.6, (found.sentence(), true_crest)
    assert "the floor rises and falls once a lap" in result.verdict, result.verdict


def test_a_tilted_boom_axis_is_said_as_a_floor_wave_with_gravity_along_the_track(recordings):
    """Plant C's tilted pivot: the floor rises and falls once a lap (+-12 mm) and gravity has a component along the
    track, m g h'(y). The floor's wave alone leaves most of the speed error; with gravity along the track in the
    same period (held out against the wave alone) both are said, each within 25 %, the gravity most forward
    where the floor climbs fastest (within 0.6 m)."""
    result = diagnose_file(recordings / "tilt.csv")
    assert [d.form for d in result.dependences] == ["tilt"], result.verdict
    found, lap = result.dependences[0], result.dependences[0].lap
    slope = 11.42 * TILT["a"] * 2 * math.pi / lap                   # the plant's g times the slope's amplitude
    assert abs(found.magnitude - TILT["a"]) <= 0.25 * TILT["a"] and found.where[0] == 1, found.sentence()
    assert abs(found.slope[0] - slope) <= 0.25 * slope, found.sentence()
    steepest = (-TILT["phi"] / (2 * math.pi) * lap) % lap
    assert min(abs(found.slope[1] - steepest), lap - abs(found.slope[1] - steepest)) <= 0.6, found.sentence()
    assert "gravity pulls along the track" in result.verdict and result.completeness.explained, result.verdict


def test_clean_recordings_depend_on_no_place_along_the_track(recordings):
    """On clean recordings of three plants (B, C and the independent one) the stage, forced to run (it runs only where the accepted effects leave
    a mismatch), finds nothing that stands on held-out strides; diagnosed, they stay clean."""
    settings, params = Settings(), load_params()
    for name in ("c_clean_a", "c_clean_b", "b_clean", "clean_1", "clean_2"):
        rec = load_recording(recordings / f"{name}.csv")
        data = prepare(rec, params, settings.min_strides, settings.liftoff_window)
        assert find_dependence(own_ramps(data), base_variant(params), settings, lap_length(settings)) == [], name
    result = diagnose_file(recordings / "b_clean.csv")
    assert result.verdict == "no significant mismatch" and not result.dependences, result.verdict


def test_without_a_track_position_the_stage_does_not_apply(recordings):
    """A forward position that is not finite, or a lap the strides do not go round, leaves the stage out: no
    dependence, on the recording whose board is found otherwise."""
    settings, params = Settings(), load_params()
    rec = load_recording(recordings / "board.csv")
    data = own_ramps(prepare(rec, params, settings.min_strides, settings.liftoff_window))
    base = base_variant(params)
    assert find_dependence(data, base, settings, 1e4) == []          # 25 m of strides on a 10 km lap
    rec.y = np.full_like(rec.y, np.nan)
    assert track_position(data, base, lap_length(settings)) is None
    assert find_dependence(data, base, settings, lap_length(settings)) == []
