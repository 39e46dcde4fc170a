"""The recordings `make test` reads stored (test/stored_recordings.py), each written again by its plant and compared
file by file with what is stored: the store is what the plants written blind write today, not a copy that drifted.

- stored_recordings_reproduced: entries whose every file is written again byte for byte; a difference raises with
  the entry and file (the harness reports it and exits 1).
- stored_recordings_entries, stored_recordings_write_s: how many, and the wall time to write them all again, two
  plant processes at a time (one per core; what `make test` no longer spends, twice over).

With --quick only the smallest entry is written again.
"""
import sys
import time
from concurrent.futures import ThreadPoolExecutor

from _common import REPO  # noqa: E402 - bench/ is on sys.path (the script's folder)

sys.path.insert(0, str(REPO / "test"))
import stored_recordings  # noqa: E402

WORKERS = 2      # plant processes at once: this machine's cores


def run(quick=False):
    entries = stored_recordings.entries()
    if not entries:
        raise RuntimeError(f"no stored recordings in {stored_recordings.STORE}")
    if quick:
        entries = [min(entries, key=lambda e: sum(f.stat().st_size for f in e.iterdir()))]
    stale = [why for why in map(stored_recordings.stale, entries) if why]
    if stale:
        raise RuntimeError("\n".join(stale))
    start = time.monotonic()
    with ThreadPoolExecutor(WORKERS) as pool:         # each writes in a process of its own
        found = list(pool.map(stored_recordings.differences, entries))
    failed = [f"{entry.name}: {diff}" for entry, diffs in zip(entries, found) for diff in diffs]
    elapsed = time.monotonic() - start
    if failed:
        raise RuntimeError("stored recordings differ from what their plants write today:\n" + "\n".join(failed))
    return [{"name": "stored_recordings_reproduced", "value": len(entries), "unit": "entries"},
            {"name": "stored_recordings_entries", "value": len(stored_recordings.entries()), "unit": "entries"},
            {"name": "stored_recordings_write_s", "value": round(elapsed, 1), "unit": "s"}]
