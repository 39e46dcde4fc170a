"""The process supervisor behind `hopper launch`: every node (or container) a process in its own
session, its output relayed line by line with its label, respawn, and the stop of them all together
(SIGINT, SIGTERM, SIGKILL after the timeouts). What it does and why: hopper_ros/launch/__init__.py.
No ROS import.
"""

from __future__ import annotations

import errno
import math
import os
import selectors
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import TextIO

DEFAULT_SIGINT_TIMEOUT = 5.0       # launch's default sigterm_timeout: SIGINT -> SIGTERM
DEFAULT_SIGTERM_TIMEOUT = 5.0      # launch's default sigkill_timeout: SIGTERM -> SIGKILL
_READ_SIZE = 65536
_MAX_LINE = 65536  # a longer line without newline is passed on in pieces
_KILL_GRACE = 2.0  # [s] after SIGKILL before we give up on a process (unkillable: not ours)


@dataclass
class ChildSpec:
    label: str
    argv: list[str]
    env: dict[str, str] | None = None
    cwd: str | None = None
    respawn: bool = False          # started again when it ends by itself (launch's `respawn`)
    respawn_delay: float = 0.0     # [s] after it ended


def _group_alive(pgid: int) -> bool:
    """Whether any live (non-zombie) process is left in process group `pgid`."""
    try:
        entries = os.listdir("/proc")
    except OSError:
        entries = None
    if entries is None:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as handle:
                stat = handle.read()
        except OSError:
            continue
        fields = stat[stat.rfind(b")") + 2 :].split()
        if len(fields) > 2 and int(fields[2]) == pgid and fields[0] not in (b"Z", b"X"):
            return True
    return False


def _child_preexec(parent_pid: int):
    """The preexec_fn of every child: the default SIGINT/SIGTERM/SIGQUIT dispositions (a launcher
    started with `&` from a script inherited SIGINT ignored, and so would its nodes: they would
    never stop on our SIGINT), and on Linux a SIGTERM to the child should the launcher itself die
    (SIGKILL included), so not even a killed launcher leaves its nodes running."""
    prctl = None
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            prctl = ctypes.CDLL(None, use_errno=True).prctl
        except (OSError, AttributeError):
            prctl = None

    def preexec() -> None:
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGQUIT):
            signal.signal(signum, signal.SIG_DFL)
        if prctl is not None:
            prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
            if os.getppid() != parent_pid:  # the launcher died before that: stop right away
                os.kill(os.getpid(), signal.SIGTERM)

    return preexec


@dataclass
class _Child:
    spec: ChildSpec
    process: subprocess.Popen
    pidfd: int | None = None
    status: int | None = None  # returncode once reaped (negative: killed by that signal)
    group_gone: bool = False
    respawned: bool = False    # ended by itself and started again: its status is not the launch's
    buffers: dict[int, bytearray] = field(default_factory=dict)

    @property
    def pgid(self) -> int:
        return self.process.pid

    def done(self) -> bool:
        if self.status is None:
            return False
        if not self.group_gone:
            self.group_gone = not _group_alive(self.pgid)
        return self.group_gone


class Launcher:
    """Start processes in their own sessions, relay their output, stop them all together."""

    def __init__(
        self,
        children: list[ChildSpec],
        *,
        sigint_timeout: float = DEFAULT_SIGINT_TIMEOUT,
        sigterm_timeout: float = DEFAULT_SIGTERM_TIMEOUT,
        out: TextIO | None = None,
        err: TextIO | None = None,
    ):
        self.specs = children
        self.sigint_timeout = sigint_timeout
        self.sigterm_timeout = sigterm_timeout
        self.out = out or sys.stdout
        self.err = err or sys.stderr
        self._children: list[_Child] = []
        self._selector = selectors.DefaultSelector()
        self._stop_requests = 0
        self._stage = 0  # 0 running, 1 SIGINT sent, 2 SIGTERM sent, 3 SIGKILL sent
        self._stage_deadline = math.inf
        self._failure: tuple[_Child | None, int] | None = None
        self._gave_up = False
        self._respawns: list[tuple[float, ChildSpec]] = []   # (when, spec) of nodes to start again
        self.respawn_counts: dict[str, int] = {}

    # -- output
    def _say(self, text: str) -> None:
        self.out.write(f"[launch] {text}\n")
        self.out.flush()

    def _emit(self, child: _Child, fd: int, data: bytes) -> None:
        stream = self.out if fd == child.process.stdout.fileno() else self.err
        stream.write(f"[{child.spec.label}] {data.decode('utf-8', 'replace')}\n")
        stream.flush()

    def _read(self, child: _Child, fd: int) -> None:
        try:
            chunk = os.read(fd, _READ_SIZE)
        except OSError as exc:
            if exc.errno in (errno.EAGAIN, errno.EINTR):
                return
            chunk = b""
        buffer = child.buffers.setdefault(fd, bytearray())
        if not chunk:  # EOF: flush the last partial line
            if buffer:
                self._emit(child, fd, bytes(buffer))
                buffer.clear()
            self._selector.unregister(fd)
            return
        buffer += chunk
        while True:
            newline = buffer.find(b"\n")
            if newline < 0:
                if len(buffer) >= _MAX_LINE:
                    self._emit(child, fd, bytes(buffer))
                    buffer.clear()
                break
            self._emit(child, fd, bytes(buffer[:newline]).rstrip(b"\r"))
            del buffer[: newline + 1]

    # -- signals
    def _on_signal(self, signum, _frame) -> None:
        self._stop_requests += 1

    def _signal_groups(self, signum: int) -> None:
        for child in self._children:
            if not child.done():
                try:
                    os.killpg(child.pgid, signum)
                except (ProcessLookupError, PermissionError):
                    pass

    def _escalate(self, now: float) -> None:
        self._stage += 1
        if self._stage == 1:
            self._signal_groups(signal.SIGINT)
            self._stage_deadline = now + self.sigint_timeout
        elif self._stage == 2:
            alive = [c.spec.label for c in self._children if not c.done()]
            self._say(f"sending SIGTERM to {', '.join(alive)}")
            self._signal_groups(signal.SIGTERM)
            self._stage_deadline = now + self.sigterm_timeout
        elif self._stage == 3:
            alive = [c.spec.label for c in self._children if not c.done()]
            self._say(f"sending SIGKILL to {', '.join(alive)}")
            self._signal_groups(signal.SIGKILL)
            self._stage_deadline = now + _KILL_GRACE

    # -- children
    def _start(self, spec: ChildSpec) -> None:
        process = subprocess.Popen(
            spec.argv,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=spec.env,
            cwd=spec.cwd,
            # a session of its own (its own process group: no terminal signals, group kill): the kernel's
            # autogroups then weigh each node as one job against a busy session beside the graph, not the
            # whole graph as one (bench_demo_load's 500 Hz runs: the graph's 1.23 cores against one core)
            start_new_session=True,
            preexec_fn=_child_preexec(os.getpid()),
        )
        child = _Child(spec, process)
        self._children.append(child)
        for stream in (process.stdout, process.stderr):
            os.set_blocking(stream.fileno(), False)
            self._selector.register(stream.fileno(), selectors.EVENT_READ, ("io", child))
        if hasattr(os, "pidfd_open"):
            try:
                child.pidfd = os.pidfd_open(process.pid)
                self._selector.register(child.pidfd, selectors.EVENT_READ, ("exit", child))
            except OSError:
                child.pidfd = None
        self._say(f"started {spec.label}: pid {process.pid}")

    def _reap(self, child: _Child) -> None:
        if child.status is not None or child.process.poll() is None:
            return
        child.status = child.process.returncode
        if child.pidfd is not None:
            self._selector.unregister(child.pidfd)
            os.close(child.pidfd)
            child.pidfd = None
        how = f"exit status {child.status}" if child.status >= 0 else f"signal {signal.Signals(-child.status).name}"
        if self._stage == 0 and child.spec.respawn:
            child.respawned = True
            count = self.respawn_counts[child.spec.label] = self.respawn_counts.get(child.spec.label, 0) + 1
            self._say(f"{child.spec.label} ended by itself ({how}); respawning it in {child.spec.respawn_delay:g} s "
                      f"(respawn {count})")
            self._respawns.append((time.monotonic() + child.spec.respawn_delay, child.spec))
        elif self._stage == 0:
            self._say(f"{child.spec.label} ended by itself ({how}); stopping the others")
            code = child.status if child.status > 0 else (128 - child.status if child.status < 0 else 1)
            self._failure = (child, code)
        else:
            self._say(f"{child.spec.label} stopped ({how})")

    # -- main loop
    def run(self) -> int:
        """Start every child and supervise until all are gone; returns the exit status."""
        previous = {}
        wakeup_r, wakeup_w = os.pipe()
        os.set_blocking(wakeup_r, False)
        os.set_blocking(wakeup_w, False)
        old_wakeup = None
        try:
            # Signals first, so a Ctrl-C during start-up is not lost; the wake-up pipe makes
            # select() return on a signal.
            old_wakeup = signal.set_wakeup_fd(wakeup_w, warn_on_full_buffer=False)
            self._selector.register(wakeup_r, selectors.EVENT_READ, ("signal", None))
            for signum in (signal.SIGINT, signal.SIGTERM):
                previous[signum] = signal.signal(signum, self._on_signal)
            for spec in self.specs:
                if self._stop_requests:
                    break
                try:
                    self._start(spec)
                except OSError as exc:
                    self._say(f"cannot start {spec.label}: {exc}; stopping the others")
                    self._failure = (None, 1)
                    break
            self._loop()
        finally:
            for signum, handler in previous.items():
                signal.signal(signum, handler)
            if old_wakeup is not None:
                signal.set_wakeup_fd(old_wakeup)
            self._selector.close()
            os.close(wakeup_r)
            os.close(wakeup_w)
            for child in self._children:
                for stream in (child.process.stdout, child.process.stderr):
                    stream.close()
                if child.pidfd is not None:
                    os.close(child.pidfd)

        if self._failure is not None:
            return self._failure[1]
        if self._gave_up or any(c.status != 0 for c in self._children if not c.respawned) or self._stage >= 2:
            return 1
        return 0

    def _loop(self) -> None:
        handled_requests = 0
        while True:
            now = time.monotonic()
            for child in self._children:
                self._reap(child)
            if self._stage == 0 and (self._failure is not None or self._stop_requests):
                if self._stop_requests and self._failure is None:
                    self._say("stopping (signal received)")
                handled_requests = self._stop_requests
                self._escalate(now)
            elif self._stage > 0 and self._stop_requests > handled_requests and self._stage < 3:
                handled_requests = self._stop_requests  # asked again: skip ahead
                self._escalate(now)
            if self._stage > 0:
                if all(c.done() for c in self._children):
                    self._drain()
                    return
                if now >= self._stage_deadline:
                    if self._stage >= 3:
                        alive = [c.spec.label for c in self._children if not c.done()]
                        self._say(f"giving up on {', '.join(alive)}: still running after SIGKILL")
                        self._gave_up = True
                        return
                    self._escalate(now)
            if self._stage == 0:
                timeout = self._respawn_due(now)
            else:
                self._respawns.clear()
                timeout = None
            # Without pidfds we look at the children now and then; while stopping, grandchildren
            # (no event for them) are checked for every 0.1 s.
            if self._stage > 0:
                timeout = max(0.0, min(0.1, self._stage_deadline - now))
            elif any(c.pidfd is None for c in self._children if c.status is None):
                timeout = 0.2 if timeout is None else min(timeout, 0.2)
            for key, _events in self._selector.select(timeout):
                self._handle(key)

    def _respawn_due(self, now: float) -> float | None:
        """Start the nodes whose respawn delay is over; seconds until the next one (None: none)."""
        due = [entry for entry in self._respawns if entry[0] <= now]
        for entry in due:
            self._respawns.remove(entry)
            try:
                self._start(entry[1])
            except OSError as exc:
                self._say(f"cannot respawn {entry[1].label}: {exc}; stopping the others")
                self._failure = (None, 1)
        return max(0.0, min(when for when, _ in self._respawns) - now) if self._respawns else None

    def _handle(self, key: selectors.SelectorKey) -> None:
        kind, child = key.data
        if kind == "io":
            self._read(child, key.fd)
        elif kind == "signal":  # the handler has counted it; just empty the wake-up pipe
            try:
                while os.read(key.fd, 512):
                    pass
            except BlockingIOError:
                pass
        # "exit": the child is reaped at the top of the loop

    def _drain(self) -> None:
        """Pass on what the stopped processes wrote last (bounded: a leaked pipe must not hang us)."""
        end = time.monotonic() + 1.0
        while time.monotonic() < end:
            io_keys = [k for k in self._selector.get_map().values() if k.data[0] == "io"]
            if not io_keys:
                return
            for key, _events in self._selector.select(max(0.0, end - time.monotonic())):
                self._handle(key)
