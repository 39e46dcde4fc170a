"""`hopper diagnose` says what it is doing, round by round, with a bar over the candidates, on a terminal; with
--quiet, or when stderr is not a terminal (a log, a pipe), it prints the result lines only."""

import os
import pty
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import stored_recordings  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.compute   # CPU-bound: `make test` runs these beside the node tests (tools/test.sh)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp("progress")
    stored_recordings.independent(folder, ("actuator_saturation",))
    return folder / "actuator_saturation.csv"


def _run_on_a_terminal(args: list[str]) -> tuple[int, str, str]:
    """Run the CLI with stderr on a pseudo-terminal; (exit code, stdout, what the terminal got)."""
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "hopper_ros.cli", *args], stdout=subprocess.PIPE, stderr=slave,
                            cwd=REPO, text=True)
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:          # the terminal closed with the process
            break
        if not chunk:
            break
        seen += chunk
    out = proc.stdout.read()
    os.close(master)
    return proc.wait(timeout=300), out, seen.decode(errors="replace")


def test_progress_on_a_terminal_round_by_round(recording):
    code, out, terminal = _run_on_a_terminal(["diagnose", str(recording)])
    assert code == 0, terminal
    assert "diagnose: round 1: locating" in terminal
    assert "diagnose: round 1: screening" in terminal and "diagnose: round 1: searching" in terminal
    assert "diagnose: round 1: torque_saturation" in terminal
    assert "/" in terminal and "#" in terminal          # a bar: [####....] done/total
    assert "missing: torque_saturation" in out and "diagnose:" not in out


def test_quiet_on_a_terminal_and_off_one(recording):
    code, out, terminal = _run_on_a_terminal(["diagnose", "--quiet", str(recording)])
    assert code == 0 and "diagnose:" not in terminal and "missing: torque_saturation" in out
    done = subprocess.run([sys.executable, "-m", "hopper_ros.cli", "diagnose", str(recording)], capture_output=True,
                          text=True, cwd=REPO, timeout=300)
    assert done.returncode == 0 and done.stderr.strip() == "", done.stderr
    assert "missing: torque_saturation" in done.stdout
