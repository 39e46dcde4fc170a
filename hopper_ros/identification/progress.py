"""A progress bar on stderr, tqdm's: redrawn in place on a terminal, one line per step otherwise
(logs, CI), the same text either way: `label [######..........] 2/5 00:03, detail`."""

from __future__ import annotations

import sys

from tqdm import tqdm

BAR_FORMAT = "{desc} [{bar:%d}] {n_fmt}/{total_fmt} {elapsed}{postfix}"
BAR_CHARACTERS = ".#"           # tqdm's ascii bar: the empty cell, then the full one
# tqdm asks the terminal for its size unless given one, and a pseudo-terminal without a size (0 x 0) makes it draw
# nothing at all: the text is not cut to the terminal's width, and one bar is shown at a time
LINE_WIDTH, ROWS = 10_000, 100


class ProgressBar:
    def __init__(self, total: int, label: str, stream=None, width: int = 24, min_interval: float = 0.2) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())
        # off a terminal tqdm draws nothing itself: `step` writes its text as a line of its own
        self._bar = tqdm(total=max(1, int(total)), desc=label, file=self.stream, bar_format=BAR_FORMAT % width,
                         ascii=BAR_CHARACTERS, ncols=LINE_WIDTH, nrows=ROWS, mininterval=min_interval, leave=True,
                         delay=0 if self._tty else float("inf"))

    @property
    def done(self) -> int:
        """Steps done so far."""
        return self._bar.n

    def note(self, detail: str) -> None:
        """Change the text after the bar (redrawn on a terminal, at most every min_interval)."""
        self._bar.set_postfix_str(detail, refresh=False)
        if self._tty:
            self._bar.update(0)         # tqdm redraws when min_interval has passed

    def step(self, detail: str = "") -> None:
        """One unit of work done."""
        self._bar.set_postfix_str(detail, refresh=False)
        if self._bar.n < self._bar.total:
            self._bar.update(1)
        if self._tty:
            self._bar.refresh()
        else:
            self.stream.write(str(self._bar) + "\n")
            self.stream.flush()

    def close(self) -> None:
        """The bar's last state on a terminal (and a new line); nothing more off one."""
        self._bar.close()
