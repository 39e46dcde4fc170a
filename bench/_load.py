"""Background load beside a run of the graph (bench_demo_load.py, soak.py): not a bench itself.

`with Load(profile, stall_target=...) as load:` starts, in processes of their own (one session and
process group, as one job beside the demo; stopped on leaving):
- `busy_per_core` x cores busy loops with normal scheduling (a CI job, a sweep beside the demo);
- `realtime`: a second SCHED_FIFO process at (priority, burst, period): busy for a burst drawn from
  [burst / 2, burst] once per period (another real-time loop on the same PC);
- `io`: a writer of `io_chunk_mb` MiB chunks with fsync, again and again (a recording, a build);
- `stall`: the process `stall_target()` names (the simulated robot) stopped with SIGSTOP for a
  duration drawn from (low, high) seconds, every `stall_every` s (a thread of this process on
  SCHED_FIFO above the graph, so the stall lasts what it should). `load.stalls` lists them.
Everything on this machine; nothing is sent anywhere.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass

STALL_PRIORITY = 80   # the stalling thread's SCHED_FIFO priority (above the graph's 50)

_BURST = """
import os, random, sys, time
priority, burst, period = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
if priority:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
rng = random.Random(int(sys.argv[4]))
while True:
    end = time.monotonic() + rng.uniform(burst / 2, burst)
    while time.monotonic() < end:
        pass
    time.sleep(max(0.0, period - burst))
"""

_JOB = """
import json, subprocess, sys, time
children = [subprocess.Popen(argv) for argv in json.loads(sys.argv[1])]
for child in children:
    child.wait()
"""

_WRITER = """
import os, sys
chunk, folder = int(sys.argv[1]) << 20, sys.argv[2]
data = os.urandom(1 << 20)
path = os.path.join(folder, "load_io.bin")
while True:
    with open(path, "wb") as handle:
        for _ in range(chunk >> 20):
            handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())
    os.remove(path)
"""


@dataclass(frozen=True)
class LoadProfile:
    name: str
    busy_per_core: int = 0
    realtime: tuple[int, float, float] | None = None    # (SCHED_FIFO priority, burst [s], period [s])
    io_chunk_mb: int = 0
    stall: tuple[float, float] | None = None             # SIGSTOP of the sim_robot for (low, high) s ...
    stall_every: float = 3.0                             # ... every this many s

    def describe(self) -> str:
        parts = []
        if self.busy_per_core:
            parts.append(f"{self.busy_per_core} busy/core")
        if self.realtime:
            priority, burst, period = self.realtime
            parts.append(f"SCHED_FIFO {priority} bursts <= {burst * 1e3:g} ms every {period * 1e3:g} ms")
        if self.io_chunk_mb:
            parts.append(f"fsync'd writes of {self.io_chunk_mb} MiB")
        if self.stall:
            parts.append(f"sim stalled {self.stall[0] * 1e3:g}-{self.stall[1] * 1e3:g} ms every {self.stall_every:g} s")
        return ", ".join(parts) or "none"


class Load:
    """The load of `profile` while inside the `with`."""

    def __init__(self, profile: LoadProfile, stall_target=lambda: None, seed: int = 0):
        self.profile, self.stall_target, self.seed = profile, stall_target, seed
        self.stalls: list[float] = []
        self._processes: list[subprocess.Popen] = []
        self._argvs: list[list[str]] = []
        self._stop = threading.Event()
        self._thread = None
        self._folder = None

    def _spawn(self, argv):
        self._argvs.append(argv)

    def _start_job(self):
        """One session and process group for the whole load, as one job beside the demo (a CI run, a
        sweep): with the kernel's autogroups a session shares the CPU with the others as one."""
        if self._argvs:
            self._processes.append(subprocess.Popen([sys.executable, "-c", _JOB, json.dumps(self._argvs)],
                                                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                                    stderr=subprocess.DEVNULL, start_new_session=True))

    def __enter__(self):
        p = self.profile
        cores = os.cpu_count() or 1
        for _ in range(p.busy_per_core * cores):
            self._spawn(["/bin/sh", "-c", "while :; do :; done"])
        if p.realtime:
            priority, burst, period = p.realtime
            self._spawn([sys.executable, "-c", _BURST, str(priority), str(burst), str(period), str(self.seed)])
        if p.io_chunk_mb:
            self._folder = tempfile.mkdtemp(prefix="hopper_load_")
            self._spawn([sys.executable, "-c", _WRITER, str(p.io_chunk_mb), self._folder])
        self._start_job()
        if p.stall:
            self._thread = threading.Thread(target=self._stall, name="stall", daemon=True)
            self._thread.start()
        return self

    def _stall(self) -> None:
        try:
            os.sched_setscheduler(threading.get_native_id(), os.SCHED_FIFO, os.sched_param(STALL_PRIORITY))
        except PermissionError:
            pass
        rng = random.Random(self.seed)
        low, high = self.profile.stall
        while not self._stop.wait(self.profile.stall_every * rng.uniform(0.7, 1.3)):
            pid = self.stall_target()
            if not pid:
                continue
            duration = rng.uniform(low, high)
            try:
                os.kill(pid, signal.SIGSTOP)
                time.sleep(duration)
            except ProcessLookupError:
                continue
            finally:
                try:
                    os.kill(pid, signal.SIGCONT)
                except ProcessLookupError:
                    pass
            self.stalls.append(duration)

    def __exit__(self, *exc_info):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        if self._processes:
            try:
                os.killpg(self._processes[0].pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        for process in self._processes:
            process.wait()
        if self._folder:
            for name in os.listdir(self._folder):
                os.remove(os.path.join(self._folder, name))
            os.rmdir(self._folder)
        return False
