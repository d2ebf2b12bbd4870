"""Run nbval (``--nbval-lax``) over an executed notebook, in a pytest of its own.

With ``--nbval-lax`` nbval re-executes every cell and fails on any cell
that raises; it compares the output only of cells tagged
``nbval-check-output`` (the notebooks mark the cell that prints their
verdicts), so a changed marked output fails too.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import nbformat

CHECKED = "nbval-check-output"
#: regexes for what differs between runs by nature (wall times, object addresses)
SANITIZE = Path(__file__).with_name("nbval_sanitize.cfg")


def for_rerun(executed: Path, dst_dir: Path) -> Path:
    """Copy an executed notebook so that its rerun writes into ``dst_dir/out``, not the run's outputs.

    Raises
    ------
    ValueError
        If the notebook has no injected ``out_dir`` to point elsewhere.
    """
    nb = nbformat.read(executed, as_version=4)
    out_dir = nb.metadata.get("papermill", {}).get("parameters", {}).get("out_dir")
    injected = [c for c in nb.cells if "injected-parameters" in c.metadata.get("tags", [])]
    quoted = [q + out_dir + q for q in ('"', "'")]  # the whole string: an upstream folder may start with it
    if not out_dir or len(injected) != 1 or not any(q in injected[0].source for q in quoted):
        raise ValueError(f"{executed}: no injected out_dir to redirect")
    new_out = dst_dir / "out"
    new_out.mkdir(parents=True, exist_ok=True)
    for q in quoted:
        injected[0].source = injected[0].source.replace(q, q[0] + str(new_out) + q[0])
    copy = dst_dir / executed.name
    nbformat.write(nb, copy)
    return copy


def checked_cells(notebook: Path) -> int:
    """How many cells nbval compares (tagged ``nbval-check-output``)."""
    nb = nbformat.read(notebook, as_version=4)
    return sum(CHECKED in c.metadata.get("tags", []) for c in nb.cells)


def run_nbval(notebook: Path, timeout_s: int = 900) -> subprocess.CompletedProcess[str]:
    """``pytest --nbval-lax notebook`` in the current environment; the result with its output.

    The rerun computes on one thread (``OMP_NUM_THREADS=1``, which torch reads as it starts), as the pipeline's
    kernels do in the run it is compared with: by default torch would take every core, and beside the other
    xdist worker the two would fight over them (a why notebook's rerun: 16 s instead of 7 s here).
    """
    cmd = [sys.executable, "-m", "pytest", "--nbval-lax", "--nbval-current-env", "--nbval-cell-timeout=600",
           f"--nbval-sanitize-with={SANITIZE}",
           # a bare pytest: without the xdist and hypothesis plugins it starts in ~0.5 s of CPU instead of ~1.5 s
           "-p", "no:cacheprovider", "-p", "no:xdist", "-p", "no:hypothesispytest", "-o", "addopts=", "-q",
           "--rootdir", str(notebook.parent), str(notebook)]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    return subprocess.run(cmd, cwd=notebook.parent, capture_output=True, text=True, timeout=timeout_s, check=False,
                          env=env)
