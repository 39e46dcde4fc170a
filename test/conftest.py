"""Test session setup: loopback-only DDS on a domain of our own, and the CLI subprocess helper.

Before any test imports rclpy:
- ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: nothing of a test leaves the machine;
- ROS_DOMAIN_ID: a domain no running participant on this machine uses (no UDP port of the
  domain's range 7400 + 250 * id ... + 249 is bound), so tests never talk to a running robot
  graph nor to another test session.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from hopper_ros.runtime.environment import free_domain_id, free_port, restore_default_stop_signals  # noqa: F401 - free_port: the tests import it from here

REPO = Path(__file__).resolve().parent.parent
SAFETY_TIMEOUT = 60.0  # [s] bound on any wait in the tests: a hang fails instead of blocking CI


os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ["ROS_DOMAIN_ID"] = str(free_domain_id())
from hopper_ros.runtime.environment import apply_ros_environment  # noqa: E402 - after the range is set

apply_ros_environment()   # LOCALHOST: the loopback profile (every DDS socket on 127.0.0.1), for children too
os.environ.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")

# Started with `&` from a script (`bash -c 'make test & wait $!'`, a CI runner), this session
# has SIGINT and SIGQUIT ignored, and every process a test starts would inherit that: a node
# then never stops on the SIGINT a test sends. The usual dispositions for us, so for them too.
RESTORED_SIGNALS = restore_default_stop_signals()


def pytest_report_header(config):
    restored = f" (restored default {', '.join(RESTORED_SIGNALS)}: started with them ignored)" if RESTORED_SIGNALS else ""
    return f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST{restored}"


def domain_id() -> int:
    return int(os.environ["ROS_DOMAIN_ID"])


# --------------------------------------------------------------------------- rclpy in-process


@pytest.fixture(scope="session")
def rclpy_session():
    """rclpy initialised once for the in-process tests (no signal handlers: pytest keeps Ctrl-C)."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    yield rclpy
    rclpy.try_shutdown()


def spin_until(executor, condition, timeout: float = SAFETY_TIMEOUT) -> bool:
    """Spin `executor` until `condition()` holds; False if the safety timeout ran out."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            return False
        executor.spin_once(timeout_sec=0.05)
    return True


# --------------------------------------------------------------------------- CLI subprocesses


class CliProcess:
    """A `hopper ...` subprocess (own process group) whose output lines are collected."""

    def __init__(self, argv: list[str], env: dict[str, str]):
        self.argv = argv
        self.process = subprocess.Popen(
            argv,
            cwd=REPO,
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            bufsize=1,
            start_new_session=True,
        )
        self.pid = self.process.pid
        self.lines = {"stdout": [], "stderr": []}
        self._changed = threading.Condition()
        self._readers = [
            threading.Thread(target=self._pump, args=(self.process.stdout, "stdout"), daemon=True),
            threading.Thread(target=self._pump, args=(self.process.stderr, "stderr"), daemon=True),
        ]
        for reader in self._readers:
            reader.start()

    def _pump(self, stream, name: str) -> None:
        for line in stream:
            with self._changed:
                self.lines[name].append(line.rstrip("\n"))
                self._changed.notify_all()
        with self._changed:
            self._changed.notify_all()

    @property
    def stdout(self) -> str:
        return "".join(line + "\n" for line in self.lines["stdout"])

    @property
    def stderr(self) -> str:
        return "".join(line + "\n" for line in self.lines["stderr"])

    def wait_for_line(self, pattern: str, stream: str = "stderr", timeout: float = SAFETY_TIMEOUT) -> re.Match:
        """The first line of `stream` matching `pattern`, waiting for it (fails if the process ends)."""
        regex = re.compile(pattern)
        end = time.monotonic() + timeout
        seen = 0
        with self._changed:
            while True:
                lines = self.lines[stream]
                for line in lines[seen:]:
                    match = regex.search(line)
                    if match:
                        return match
                seen = len(lines)
                left = end - time.monotonic()
                if left <= 0 or (self.process.poll() is not None and not any(r.is_alive() for r in self._readers)):
                    raise AssertionError(
                        f"no line matching {pattern!r} on {stream} of {self.argv[3:]} "
                        f"(exit status {self.process.poll()})\n--- stdout\n{self.stdout}--- stderr\n{self.stderr}"
                    )
                self._changed.wait(min(left, 0.5))

    def wait(self, timeout: float = SAFETY_TIMEOUT) -> int:
        try:
            status = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.signal(signal.SIGUSR1)      # the hopper CLI writes every thread's stack (faulthandler)
            time.sleep(1.0)
            raise AssertionError(f"{self.argv[3:]} still running after {timeout} s\n--- stdout\n{self.stdout}"
                                 f"--- stderr\n{self.stderr}") from None
        for reader in self._readers:
            reader.join(timeout)
        return status

    def signal(self, signum: int) -> None:
        self.process.send_signal(signum)

    def kill_group(self) -> None:
        try:
            os.killpg(self.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


@pytest.fixture
def hopper_cli():
    """spawn(*args, env=None, unset=()) -> CliProcess running `python -m hopper_ros.cli *args`.

    The child gets this session's environment (LOCALHOST, our domain), plus `env`, minus the
    names in `unset`. Whatever is left running at the end of the test is killed (whole group).
    """
    spawned: list[CliProcess] = []

    def spawn(*args: str, env: dict[str, str] | None = None, unset: tuple[str, ...] = ()) -> CliProcess:
        child_env = dict(os.environ)
        child_env.update(env or {})
        for name in unset:
            child_env.pop(name, None)
        child_env["PYTHONUNBUFFERED"] = "1"
        paths = [str(REPO)] + [p for p in child_env.get("PYTHONPATH", "").split(os.pathsep) if p]
        child_env["PYTHONPATH"] = os.pathsep.join(paths)
        process = CliProcess([sys.executable, "-m", "hopper_ros.cli", *args], child_env)
        spawned.append(process)
        return process

    yield spawn
    for process in spawned:
        if process.process.poll() is None:
            process.kill_group()
            process.process.wait(10)
        else:
            process.kill_group()  # leftovers of its group, if any


def process_group_members(pgid: int) -> list[int]:
    """Live (non-zombie) processes of a process group, from /proc."""
    members = []
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_bytes()
        except OSError:
            continue
        fields = stat[stat.rfind(b")") + 2 :].split()
        if int(fields[2]) == pgid and fields[0] not in (b"Z", b"X"):
            members.append(int(entry))
    return members


def process_alive(pid: int) -> bool:
    """True while `pid` exists and is not a zombie."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return False
    return stat[stat.rfind(b")") + 2 :].split()[0] not in (b"Z", b"X")


def run_without_numba(script: str) -> subprocess.CompletedProcess:
    """`script` run by this interpreter in the repository with numba unimportable (the numpy path)."""
    return subprocess.run([sys.executable, "-c", "import sys; sys.modules['numba'] = None\n" + script],
                          capture_output=True, text=True, cwd=REPO, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(REPO)})
