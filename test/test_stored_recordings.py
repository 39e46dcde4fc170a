"""The stored recordings of the plants written blind (test/stored_recordings.py): every entry holds what its command
writes with today's plant and config, one is written again here and compared file by file (all of them in
`make bench`, bench/bench_stored_recordings.py), and a command the store lacks is run and then served stored."""

import json

import pytest

import stored_recordings

# a command that writes what no two runs write alike (its process id), a large file and a small one
PID_WRITER = """
    import os
    import sys
    from pathlib import Path
    Path(sys.argv[1], "big.csv").write_text("t,pid\\n" + "".join(f"{k},{os.getpid()}\\n" for k in range(2000)))
    Path(sys.argv[1], "small.json").write_text(str(os.getpid()))
    """


def test_every_stored_entry_was_written_by_todays_plant_and_config():
    entries = stored_recordings.entries()
    assert len(entries) >= 10, "the store is empty: " + stored_recordings.REFRESH
    stale = [why for why in map(stored_recordings.stale, entries) if why]
    assert not stale, "\n".join(stale)


@pytest.mark.compute
def test_a_stored_entry_is_what_its_plant_writes_today():
    """The smallest entry of the independent plant (about 4 s to write), written again: every file byte for byte."""
    ours = [e for e in stored_recordings.entries()
            if json.loads((e / "manifest.json").read_text())["plant"] == "independent_plant"]
    entry = min(ours, key=lambda e: sum(f.stat().st_size for f in e.iterdir()))
    assert stored_recordings.differences(entry) == []


def test_a_command_the_store_lacks_is_run_then_served_stored(tmp_path, monkeypatch):
    monkeypatch.setattr(stored_recordings, "STORE", tmp_path / "store")
    monkeypatch.setenv("HOPPER_STORE_RECORDINGS", "1")
    first = stored_recordings.written(tmp_path / "first", "plant_c", PID_WRITER)
    (entry,) = stored_recordings.entries()
    assert sorted(p.name for p in entry.iterdir()) == ["big.csv.xz", "manifest.json", "small.json"]
    assert entry.stat().st_size and (entry / "big.csv.xz").stat().st_size < (first / "big.csv").stat().st_size / 5
    second = stored_recordings.written(tmp_path / "second", "plant_c", PID_WRITER)
    for name in ("big.csv", "small.json"):      # the same process id: unpacked, not written again
        assert (second / name).read_bytes() == (first / name).read_bytes()
    assert stored_recordings.stale(entry) is None
    assert stored_recordings.differences(entry) == ["big.csv: differs", "small.json: differs"]


def test_an_entry_whose_plant_changed_is_stale_and_named(tmp_path, monkeypatch):
    monkeypatch.setattr(stored_recordings, "STORE", tmp_path / "store")
    monkeypatch.setenv("HOPPER_STORE_RECORDINGS", "1")
    stored_recordings.written(tmp_path / "out", "plant_c", PID_WRITER)
    (entry,) = stored_recordings.entries()
    manifest = json.loads((entry / "manifest.json").read_text())
    manifest["sources"]["test/plant_c/plant.py"] = "0" * 64         # as if plant.py had changed since
    (entry / "manifest.json").write_text(json.dumps(manifest))
    why = stored_recordings.stale(entry)
    assert why.startswith(entry.name) and "test/plant_c/plant.py changed" in why and "HOPPER_STORE_RECORDINGS=1" in why
