"""nbval over the notebooks the smoke profile executed, and nbval failing on a broken cell."""

from __future__ import annotations

from pathlib import Path

import nbformat
import pytest

from fnnbook import load_spec
from reader.nbval_run import CHECKED, checked_cells, for_rerun, run_nbval

ROOT = Path(__file__).resolve().parents[2]
_SPEC = load_spec(ROOT / "pipeline.yaml")
#: every task but a grid's points (their aggregate step shows what they computed, and is checked)
TASKS = [t for t in _SPEC.declares("smoke") if not any(t in points for points in _SPEC.grids.values())]


@pytest.mark.notebook
@pytest.mark.parametrize("task", TASKS)
def test_executed_notebook_passes_nbval(smoke_outputs, task: str, tmp_path: Path) -> None:
    report = smoke_outputs.run([task])
    assert report.ok, [(o.task, o.status, o.message) for o in report.outcomes]
    notebook = for_rerun(smoke_outputs.dir(task) / f"{task}.ipynb", tmp_path)
    assert checked_cells(notebook) >= 1, f"{task}: no cell tagged {CHECKED} for nbval to compare"
    done = run_nbval(notebook)
    assert done.returncode == 0, f"nbval failed on {task}:\n{done.stdout[-4000:]}\n{done.stderr[-2000:]}"
    assert " passed" in done.stdout


def _notebook(path: Path, cells: list[nbformat.NotebookNode]) -> Path:
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.metadata["papermill"] = {"parameters": {"out_dir": "/nonexistent/out"}}
    nb.cells = [nbformat.v4.new_code_cell('out_dir = "/nonexistent/out"', metadata={"tags": ["injected-parameters"]}),
                *cells]
    nbformat.write(nb, path)
    return path


def _printed(source: str, text: str, tags: list[str]) -> nbformat.NotebookNode:
    return nbformat.v4.new_code_cell(source, metadata={"tags": tags}, execution_count=1,
                                     outputs=[nbformat.v4.new_output("stream", name="stdout", text=text)])


def test_nbval_fails_on_a_raising_cell_and_on_a_changed_marked_output(tmp_path: Path) -> None:
    cells = [_printed("print('S1: reproduced')", "S1: reproduced\n", [CHECKED]),  # same output: passes
             _printed("import time; print(time.time())", "0\n", []),  # unmarked: may differ
             _printed("import torch; print(torch.get_num_threads())", "1\n", [CHECKED]),  # one thread, as the run
             _printed("print('S1: partly')", "S1: reproduced\n", [CHECKED]),  # a marked output that changed
             nbformat.v4.new_code_cell("raise RuntimeError('a broken cell')")]
    notebook = for_rerun(_notebook(tmp_path / "src.ipynb", cells), tmp_path / "run")
    done = run_nbval(notebook, timeout_s=300)
    assert done.returncode == 1, done.stdout[-3000:]
    assert "2 failed, 4 passed" in done.stdout, done.stdout[-3000:]  # the injected cell and the first three pass
    failed = [line.split(" - ")[0] for line in done.stdout.splitlines() if line.startswith("FAILED")]
    assert failed == ["FAILED src.ipynb::Cell 4", "FAILED src.ipynb::Cell 5"], failed  # changed, raised
    assert "S1: partly" in done.stdout  # nbval shows the new output against the stored one
    assert "a broken cell" in done.stdout
