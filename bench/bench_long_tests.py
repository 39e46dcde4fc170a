"""The tests long by nature (`pytest.mark.long`: a diagnosis of a minute or more each), which `make test` leaves
out to stay within its 10 minutes (tools/test.sh): run here as one pytest session, one numba thread, as make test
runs its compute sessions.

- long_tests_passed, long_tests_s: the session's count and wall time. A failure raises with pytest's report (the
  harness reports it and exits 1).

With --quick nothing runs (each of these tests is a whole diagnosis).
"""
import re
import subprocess
import sys
import time

from _common import REPO, child_env  # noqa: E402 - bench/ is on sys.path (the script's folder)


def run(quick=False):
    if quick:
        return []
    env = child_env()
    env["NUMBA_NUM_THREADS"] = "1"
    start = time.monotonic()
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "long", "test"],
                            cwd=REPO, env=env, capture_output=True, text=True, timeout=3600)
    elapsed = time.monotonic() - start
    counts = {word: int(number) for number, word in re.findall(r"(\d+) (passed|failed)", result.stdout)}
    if result.returncode != 0:
        raise RuntimeError(f"pytest -m long exited {result.returncode}:\n{result.stdout[-4000:]}")
    return [{"name": "long_tests_passed", "value": counts.get("passed", 0), "unit": "tests"},
            {"name": "long_tests_s", "value": round(elapsed, 1), "unit": "s"}]
