"""Recordings of the plants written blind (test/plant_b/, test/plant_c/, test/independent_plant/), stored as test data.

A plant B recording takes 14 s to write (solve_ivp through 50 strides); the diagnosis tests wrote about thirty
recordings of the three plants in every `make test`, 230 s of CPU. What a plant writes is a fixed function of the
command that writes it, the plant's own files and the two files of config/ the plants read, so each command's output
is stored once, under a key of exactly those (test/data/recordings/<key>/: the files, CSVs xz-compressed, and
`manifest.json`: the command and a hash of each source). `written` unpacks the stored files; where there are none
for that key (a new command, a plant or config/model.yaml changed) it runs the command, and with
HOPPER_STORE_RECORDINGS=1 stores what it wrote.

Kept honest twice: test_stored_recordings.py holds every entry's key to today's sources (a stale entry fails with
the command that refreshes it) and writes one entry again to compare; `make bench` writes every entry again and
compares them all (bench/bench_stored_recordings.py).
"""

from __future__ import annotations

import hashlib
import json
import lzma
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
STORE = HERE / "data" / "recordings"
CONFIG_READ = ("config/model.yaml", "config/hardware.yaml")     # what the plants read of ours (their load_params)
PACKED = ".xz"                                                  # suffix of a stored file compressed
SMALL = 4096                                                    # [bytes] files up to this are stored as they are
TIMEOUT = 900.0                                                 # [s] a hang guard on a command; no speed asserted
# every test that reads the store (test_diagnosis_yardstick.py among them is not marked `compute`)
REFRESH = "HOPPER_STORE_RECORDINGS=1 .venv/bin/python -m pytest $(grep -l stored_recordings test/test_*.py)"


def _sources(plant: str) -> dict:
    """Repo-relative path -> sha256 of every file the plant `plant` (a folder of test/) is made of, and of the
    config files it reads."""
    files = sorted(p for p in (HERE / plant).rglob("*") if p.is_file() and "__pycache__" not in p.parts)
    files += [REPO / name for name in CONFIG_READ]
    return {p.relative_to(REPO).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest() for p in files}


def _key(command: dict) -> str:
    return hashlib.sha256(json.dumps(command, sort_keys=True).encode()).hexdigest()[:20]


def command_of(plant: str, code: str, cwd: str = "test") -> dict:
    """The stored command: Python source `code` run in `cwd` (repo-relative) with the output folder as argv[1],
    and the sources of the plant it runs."""
    return {"code": textwrap.dedent(code), "cwd": cwd, "plant": plant, "sources": _sources(plant)}


# numpy's SIMD levels up to the one the store was written with: its AVX-512 loops (exp, sin, ...) round some last
# digits otherwise, and a recording written on a CPU that has them differed from the stored one in its 14th digit
SIMD_KEPT = ("X86_V2", "X86_V3")


def plant_environment() -> dict:
    """The environment a plant writes in: numpy's CPU dispatch held to SIMD_KEPT (NPY_DISABLE_CPU_FEATURES, only
    with what this CPU has beyond them: numpy warns of a feature it lacks)."""
    import numpy

    found = numpy.__config__.CONFIG.get("SIMD Extensions", {}).get("found", [])
    beyond = [feature for feature in found if feature not in SIMD_KEPT]
    return dict(os.environ, NPY_DISABLE_CPU_FEATURES=" ".join(beyond)) if beyond else dict(os.environ)


def run(command: dict, folder: Path) -> None:
    """Write the command's recordings into `folder` with the plant itself (a process of its own)."""
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, "-c", command["code"], str(folder)], check=True, capture_output=True,
                   timeout=TIMEOUT, cwd=REPO / command["cwd"], env=plant_environment())


def unpack(entry: Path, folder: Path) -> list:
    """The stored files of `entry` into `folder`, decompressed; their names."""
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for stored in sorted(entry.iterdir()):
        if stored.name == "manifest.json":
            continue
        name = stored.name[:-len(PACKED)] if stored.name.endswith(PACKED) else stored.name
        data = lzma.decompress(stored.read_bytes()) if stored.name.endswith(PACKED) else stored.read_bytes()
        (folder / name).write_bytes(data)
        names.append(name)
    return names


def store(command: dict, produced: list, folder: Path) -> Path:
    """Keep the files `produced` (names in `folder`) as the entry of `command`."""
    entry = STORE / _key(command)
    partial = Path(tempfile.mkdtemp(dir=STORE.parent, prefix=".recording-"))
    for name in produced:
        data = (folder / name).read_bytes()
        if len(data) > SMALL:
            (partial / (name + PACKED)).write_bytes(lzma.compress(data, preset=9 | lzma.PRESET_EXTREME))
        else:
            (partial / name).write_bytes(data)
    (partial / "manifest.json").write_text(json.dumps(command, indent=1, sort_keys=True) + "\n")
    STORE.mkdir(parents=True, exist_ok=True)
    try:
        partial.rename(entry)
    except OSError:              # another session stored the same command meanwhile
        shutil.rmtree(partial)
    return entry


def written(folder: Path, plant: str, code: str, cwd: str = "test") -> Path:
    """`folder` with the recordings that `code` writes with the plant `plant` (see command_of): the stored ones
    where the store has them for today's sources, else written now (and stored with HOPPER_STORE_RECORDINGS=1)."""
    command = command_of(plant, code, cwd)
    entry = STORE / _key(command)
    if (entry / "manifest.json").is_file():
        unpack(entry, folder)
        return folder
    with tempfile.TemporaryDirectory() as fresh:
        run(command, Path(fresh))
        produced = sorted(p.name for p in Path(fresh).iterdir())
        folder.mkdir(parents=True, exist_ok=True)
        for name in produced:
            shutil.copyfile(Path(fresh) / name, folder / name)
        if os.environ.get("HOPPER_STORE_RECORDINGS") == "1":
            store(command, produced, Path(fresh))
    return folder


def independent(folder: Path, names) -> Path:
    """The independent plant's recordings `names` (its write_suite), one stored entry each."""
    for name in names:
        written(folder, "independent_plant", f"""
            import sys
            from independent_plant.suite import write_suite
            write_suite(sys.argv[1], [{name!r}])
            """)
    return folder


def plant_b(folder: Path, code: str) -> Path:
    """Plant B's recordings written by `code` (run in test/, `from plant_b ...`)."""
    return written(folder, "plant_b", code)


def plant_c(folder: Path, code: str) -> Path:
    """Plant C's recordings written by `code` (run in test/plant_c/, `from suite import ...`)."""
    return written(folder, "plant_c", code, cwd="test/plant_c")


def entries() -> list:
    """Every stored entry's folder."""
    return sorted(p for p in STORE.iterdir() if (p / "manifest.json").is_file()) if STORE.is_dir() else []


def stale(entry: Path) -> str | None:
    """Why `entry` no longer holds what its command writes today (a source changed), or None."""
    command = json.loads((entry / "manifest.json").read_text())
    today = _sources(command["plant"])
    changed = sorted(k for k in command["sources"].keys() | today.keys() if command["sources"].get(k) != today.get(k))
    if changed:
        return (f"{entry.name}: {', '.join(changed)} changed since it was stored; refresh: "
                f"rm -r {os.path.relpath(entry, REPO)} && {REFRESH}")
    if _key(command) != entry.name:
        return f"{entry.name}: its manifest's key is {_key(command)}"
    return None


def differences(entry: Path) -> list:
    """The files of `entry` that differ from what its command writes today (written again now)."""
    command = json.loads((entry / "manifest.json").read_text())
    with tempfile.TemporaryDirectory() as tmp:
        stored_files, fresh = Path(tmp) / "stored", Path(tmp) / "fresh"
        names = unpack(entry, stored_files)
        run(command, fresh)
        today = sorted(p.name for p in fresh.iterdir())
        out = [f"{name}: not written today" for name in names if name not in today]
        out += [f"{name}: written today, not stored" for name in today if name not in names]
        out += [f"{name}: differs" for name in names
                if name in today and (stored_files / name).read_bytes() != (fresh / name).read_bytes()]
    return out
