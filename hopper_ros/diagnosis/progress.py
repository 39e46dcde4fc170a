"""What `hopper diagnose` is doing, round by round, with a bar where it loops over candidates: on stderr when
it is a terminal, silent otherwise or when quiet (logs and pipes get the result lines only)."""

from __future__ import annotations

import sys
from contextlib import contextmanager

from hopper_ros.identification.progress import ProgressBar


class Progress:
    def __init__(self, stream=None, enabled: bool | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = bool(getattr(self.stream, "isatty", lambda: False)()) if enabled is None else enabled
        self.stage = ""

    def say(self, text: str) -> None:
        """A step of the diagnosis (also the label of the bars that follow)."""
        self.stage = text
        if self.enabled:
            self.stream.write(f"diagnose: {text}\n")
            self.stream.flush()

    @contextmanager
    def bar(self, total: int, label: str):
        """A bar over `total` items; yields a function to call once per item (with a short detail)."""
        if not self.enabled or total <= 1:
            yield lambda detail="": None
            return
        bar = ProgressBar(total, f"  {label}", stream=self.stream)
        try:
            yield bar.step
        finally:
            bar.close()


QUIET = Progress(enabled=False)
