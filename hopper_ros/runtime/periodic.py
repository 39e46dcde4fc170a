"""A periodic action on a thread of its own, on time whatever the rest of the process is busy with
(no ROS). The deadbeat controller repeats its motor command with it (issue 29: from an executor
timer, the repeats waited behind the sensing chain's callbacks and the other processes of the loop,
and the driver saw gaps of 10-30 ms in the command stream).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from typing import Callable


class PeriodicThread:
    """`action()` every `period` seconds on CLOCK_MONOTONIC, from a daemon thread. A wake-up that came
    late is not made up for with a burst: the next one is a period after it. When the process runs
    on SCHED_FIFO the thread runs `boost` priorities above it (the real-time loop of equal priority
    cannot hold it back; it does little each time), and the interpreter's switch interval is
    lowered to a tenth of the period so that a running callback hands it the GIL within that. An
    exception in `action` goes to `on_error` and ends the thread: a stream that cannot be computed stops."""

    def __init__(self, period: float, action: Callable[[], None], boost: int = 0, name: str = "periodic",
                 on_error: Callable[[BaseException], None] = lambda exc: None) -> None:
        if not period > 0.0:
            raise ValueError(f"period must be > 0 s, got {period!r}")
        self.period, self.action, self.boost, self.on_error = period, action, boost, on_error
        self.priority = 0            # the thread's SCHED_FIFO priority once running (0: normal scheduling)
        self.late_max = 0.0          # [s] the latest wake-up so far
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def start(self) -> "PeriodicThread":
        sys.setswitchinterval(min(sys.getswitchinterval(), self.period / 10))
        self._thread.start()
        return self

    def stop(self, timeout: float = 1.0) -> None:
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)

    def _boost(self) -> None:
        try:
            if os.sched_getscheduler(0) != os.SCHED_FIFO or not self.boost:
                return
            priority = min(os.sched_get_priority_max(os.SCHED_FIFO), os.sched_getparam(0).sched_priority + self.boost)
            os.sched_setscheduler(threading.get_native_id(), os.SCHED_FIFO, os.sched_param(priority))
            self.priority = priority
        except (OSError, AttributeError):
            pass                      # not permitted or not Linux: the process's own scheduling

    def _run(self) -> None:
        self._boost()
        deadline = time.monotonic()
        while True:
            deadline += self.period
            wait = deadline - time.monotonic()
            if wait > 0.0:
                if self._stop.wait(wait):
                    return
            else:
                self.late_max = max(self.late_max, -wait)
                deadline = time.monotonic()
                if self._stop.is_set():
                    return
            try:
                self.action()
            except Exception as exc:  # noqa: BLE001 - reported by the owner; the repeats end (fail safe)
                self.on_error(exc)
                return
