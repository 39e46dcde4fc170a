"""SIGINT/SIGTERM as a stop request that wakes an rclpy executor at once (nodes, `hopper topic`,
`hopper bag record`)."""

from __future__ import annotations

import os
import signal
import threading

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopSignals:
    """SIGINT/SIGTERM as a stop request that also wakes an rclpy executor at once.

    rclpy's own signal handlers are not used: with them a SIGINT arriving while the executor
    builds its wait set was seen to be lost (the node then waited forever). Here the Python
    handlers record the signal, and `signal.set_wakeup_fd` makes the interpreter's C handler
    write the signal number to a pipe at signal time; a watcher thread reads it and triggers a
    guard condition of the attached node, which wakes the executor's wait.
    """

    def __init__(self) -> None:
        self.received: int | None = None
        self._guard = None
        self._previous: dict[int, object] = {}
        self._old_wakeup_fd: int | None = None
        self._pipe: tuple[int, int] | None = None
        self._watcher: threading.Thread | None = None

    def install(self) -> "StopSignals":
        if threading.current_thread() is not threading.main_thread():
            return self  # only the main thread can handle signals: the caller's job then
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)
        self._pipe = (read_fd, write_fd)
        self._old_wakeup_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        for signum in _STOP_SIGNALS:
            if signal.getsignal(signum) == signal.SIG_IGN:
                continue  # ignored by whoever started us (e.g. `cmd &` in a script): keep it so
            self._previous[signum] = signal.signal(signum, self._on_signal)
        self._watcher = threading.Thread(target=self._watch, name="stop-signals", daemon=True)
        self._watcher.start()
        return self

    def _on_signal(self, signum: int, _frame) -> None:
        if self.received is None:
            self.received = signum

    def _watch(self) -> None:
        while True:
            try:
                data = os.read(self._pipe[0], 64)
            except OSError:
                return
            if not data:
                return
            for signum in data:
                if signum in self._previous:
                    if self.received is None:
                        self.received = signum
                    guard = self._guard
                    if guard is not None:
                        try:
                            guard.trigger()
                        except Exception:  # noqa: BLE001 - destroyed meanwhile: nothing to wake
                            pass

    def attach(self, node) -> None:
        """Wake the executor spinning `node` when a stop signal arrives."""
        self._guard = node.create_guard_condition(lambda: None)
        if self.received is not None:
            self._guard.trigger()

    def detach(self) -> None:
        self._guard = None

    def uninstall(self) -> None:
        self._guard = None
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()
        if self._pipe is not None:
            signal.set_wakeup_fd(self._old_wakeup_fd if self._old_wakeup_fd is not None else -1)
            os.close(self._pipe[1])  # the watcher reads EOF and ends
            self._watcher.join(1.0)
            os.close(self._pipe[0])
            self._pipe = None
