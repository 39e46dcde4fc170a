"""The tests long by nature (`pytest.mark.long`: a diagnosis of a minute or more each), which `make test` leaves
out to stay within its 10 minutes (tools/test.sh): run here as two pytest sessions side by side (one core each, one
numba thread, as make test runs its compute sessions): test_diagnosis_alternatives.py's, and all the others.

- long_tests_passed, long_tests_s: the sessions' count and wall time. A failure raises with pytest's report (the
  harness reports it and exits 1).

With --quick nothing runs (each of these tests is a whole diagnosis).
"""
import re
import subprocess
import sys
import time

from _common import REPO, child_env  # noqa: E402 - bench/ is on sys.path (the script's folder)


SPLIT = "test/test_diagnosis_alternatives.py"      # about half of the long tests' CPU


def run(quick=False):
    if quick:
        return []
    env = child_env()
    env["NUMBA_NUM_THREADS"] = "1"
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-m", "long"]
    start = time.monotonic()
    sessions = [subprocess.Popen(command + args, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 text=True) for args in ([SPLIT], [f"--ignore={SPLIT}", "test"])]
    outputs = [session.communicate(timeout=3600)[0] for session in sessions]
    elapsed = time.monotonic() - start
    passed = 0
    for session, output in zip(sessions, outputs):
        if session.returncode != 0:
            raise RuntimeError(f"pytest -m long exited {session.returncode}:\n{output[-4000:]}")
        passed += sum(int(n) for n in re.findall(r"(\d+) passed", output))
    return [{"name": "long_tests_passed", "value": passed, "unit": "tests"},
            {"name": "long_tests_s", "value": round(elapsed, 1), "unit": "s"}]
