"""The ``fnn-pipeline`` command's entry point: a Ctrl-C while the command still imports its modules (dask,
papermill, torch take seconds) ends it with one line and exit status 130, as one later does, not a traceback.

A KeyboardInterrupt raised inside those imports is not safe to catch: raised in code that a C extension runs
(torch's pybind11 bindings) it aborts the process (SIGABRT), and raised in code run through ``exec`` (dataclasses,
numpy, scipy do this at import time) it makes CPython kill itself with SIGINT at exit, whatever status the program
returns. So during the imports a Ctrl-C never becomes an exception: the handler below ends the process at once
(nothing has been started yet that would need cleaning up)."""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Sequence
from types import FrameType

__all__ = ["main"]

#: the exit status of a command ended by Ctrl-C (128 + SIGINT), as a shell reports it
INTERRUPTED = 130


def _end_now(_signum: int, _frame: FrameType | None) -> None:
    """SIGINT while importing: one line, exit 130, no exception unwinding through half-imported modules."""
    sys.stdout.flush()
    print("interrupted", file=sys.stderr, flush=True)
    os._exit(INTERRUPTED)


def main(argv: Sequence[str] | None = None) -> int:
    """Import the command line (:mod:`fnnbook.cli`) and run it; Ctrl-C at any moment: ``interrupted``, 130."""
    before = signal.getsignal(signal.SIGINT)
    if before is not signal.SIG_IGN:  # a command started with Ctrl-C ignored (nohup, a worker) keeps it ignored
        signal.signal(signal.SIGINT, _end_now)
    try:
        from fnnbook.cli import main as command  # noqa: PLC0415 (the imports a Ctrl-C may cut short)
    finally:
        signal.signal(signal.SIGINT, before)
    try:
        return command(argv)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return INTERRUPTED
