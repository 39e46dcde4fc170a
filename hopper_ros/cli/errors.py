"""One line, never a traceback, for the offline tools' bad input (issue 17).

`run_tool(tool, inputs, func)` runs a command's work and turns whatever it raises into one line
on stderr, `hopper TOOL: error: FILE: what is wrong`, and exit status 3 (BAD_INPUT, cli/exit_codes.py): the errors of the
loaders (RecordingError, BagError, ValueError, OSError: they name the file already; the input is
prefixed when they do not), running out of memory, and any other exception, with its type
(a defect rather than bad input: `HOPPER_DEBUG=1` shows its traceback). Ctrl-C is left alone.
"""

from __future__ import annotations

import os
import sys
import traceback
from typing import Callable, Sequence

from hopper_ros.cli.exit_codes import BAD_INPUT as INPUT_ERROR  # noqa: E402 - the table of every tool
_MAX_MESSAGE = 400


def describe(exc: BaseException, inputs: Sequence[str] = ()) -> str:
    """`exc` as one line that names the input file."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, MemoryError):
        text = "not enough memory to load it"
    elif isinstance(exc, OSError) and exc.filename is not None and str(exc.filename) not in text:
        text = f"{exc.filename}: {exc.strerror or text}"
    elif not isinstance(exc, (ValueError, OSError, KeyError, LookupError)):
        text = f"{type(exc).__name__}: {text} (unexpected: HOPPER_DEBUG=1 shows where)"
    named = [str(p) for p in inputs if p]
    if named and not any(name in text for name in named):
        text = f"{named[0]}: {text}"
    if len(text) > _MAX_MESSAGE:
        text = text[:_MAX_MESSAGE - 3] + "..."
    return text


def run_tool(tool: str, inputs: Sequence[str], func: Callable[[], int]) -> int:
    try:
        return func()
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # noqa: BLE001 - the point: one line whatever went wrong
        print(f"hopper {tool}: error: {describe(exc, inputs)}", file=sys.stderr)
        if os.environ.get("HOPPER_DEBUG"):
            traceback.print_exc()
        return INPUT_ERROR
