"""A plain-text progress bar on stderr (no dependency): redrawn in place on a terminal, one
line per step otherwise (logs, CI)."""

from __future__ import annotations

import sys
import time


class ProgressBar:
    def __init__(self, total: int, label: str, stream=None, width: int = 24, min_interval: float = 0.2) -> None:
        self.total = max(1, int(total))
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.min_interval = min_interval
        self.done = 0
        self.detail = ""
        self.started = time.monotonic()
        self._last_draw = 0.0
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def note(self, detail: str) -> None:
        """Change the text after the bar (redrawn on a terminal, at most every min_interval)."""
        self.detail = detail
        if self._tty and time.monotonic() - self._last_draw >= self.min_interval:
            self._draw()

    def step(self, detail: str = "") -> None:
        """One unit of work done."""
        self.done = min(self.total, self.done + 1)
        self.detail = detail
        self._draw(final_line=not self._tty)

    def close(self) -> None:
        if self._tty:
            self.stream.write("\n")
            self.stream.flush()

    def _draw(self, final_line: bool = False) -> None:
        self._last_draw = time.monotonic()
        filled = int(self.width * self.done / self.total)
        elapsed = time.monotonic() - self.started
        text = (f"{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {self.done}/{self.total} "
                f"{elapsed:5.1f} s {self.detail}")
        if self._tty:
            self.stream.write("\r" + text + "\033[K")
        elif final_line:
            self.stream.write(text + "\n")
        else:
            return
        self.stream.flush()
