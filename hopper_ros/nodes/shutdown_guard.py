"""A ROS teardown that hangs must not keep a process from ending.

rclpy's `Node.destroy_node` and `rclpy.try_shutdown` end in the DDS participant's teardown, which was
seen to hang under load (CI, twice: a recorder after its bag was closed, the motor driver after the
drive had confirmed it was disabled, both inside rclpy's native `destroy_when_not_in_use`). The work
that matters is done before it: `ShutdownGuard` gives the teardown SHUTDOWN_GRACE seconds, then says so on
stderr with every thread's stack and ends the process with the status it was going to return.

That timer is a Python thread: it cannot run while the teardown's native call holds the interpreter's lock, as
rclpy's `Publisher.destroy` did in an event detector (make test, 2026-11-28: its timer and signal watcher waiting
for the lock, still running 60 s after SIGINT). faulthandler's own watchdog, a thread of C that needs no lock,
ends such a process BACKSTOP seconds later with the stacks and status 1 (faulthandler's, not a choice here).
"""

from __future__ import annotations

import faulthandler
import os
import sys
import threading

SHUTDOWN_GRACE = 10.0   # [s] the ROS teardown's time once a process's own work is done
BACKSTOP = 5.0          # [s] after it, the end of a teardown that holds the interpreter's lock (status 1)


class ShutdownGuard:
    """`with ShutdownGuard(who, done, status): <ROS teardown>`: if the block has not ended after
    SHUTDOWN_GRACE seconds, print "<who>: the ROS shutdown has not ended in N s (<done>); ...", the stacks,
    and `os._exit(status)`."""

    def __init__(self, who: str, done: str, status: int) -> None:
        self.who, self.done, self.status = who, done, status
        self.grace = SHUTDOWN_GRACE      # read now: a test sets the module's value before the process starts
        self._timer: threading.Timer | None = None

    def __enter__(self) -> "ShutdownGuard":
        self._timer = threading.Timer(self.grace, self._give_up)
        self._timer.daemon = True
        self._timer.start()
        self._backstop = True
        try:
            faulthandler.dump_traceback_later(self.grace + BACKSTOP, exit=True, file=sys.stderr)
        except (AttributeError, ValueError, OSError, RuntimeError):    # stderr is no file (captured): the timer alone
            self._backstop = False
        return self

    def __exit__(self, *exc_info) -> None:
        self._timer.cancel()
        if self._backstop:
            faulthandler.cancel_dump_traceback_later()

    def _give_up(self) -> None:
        print(f"{self.who}: the ROS shutdown has not ended in {self.grace:.0f} s ({self.done}); "
              f"exiting with status {self.status}; where each thread stands:", file=sys.stderr, flush=True)
        try:
            faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
        except (AttributeError, ValueError, OSError):   # stderr is no file (captured): the line above is all
            pass
        sys.stdout.flush()
        os._exit(self.status)
