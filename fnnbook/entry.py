"""The ``fnn-pipeline`` command's entry point: a Ctrl-C while the command still imports its modules (dask,
papermill, torch take seconds) ends it with one line and exit status 130, as one later does, not a traceback."""

from __future__ import annotations

import sys
from collections.abc import Sequence

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """Import the command line (:mod:`fnnbook.cli`) and run it; Ctrl-C at any moment: ``interrupted``, 130."""
    try:
        from fnnbook.cli import main as command  # noqa: PLC0415 (the imports a Ctrl-C may cut short)

        return command(argv)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
