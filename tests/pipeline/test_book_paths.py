"""A page of the book shows no path of the machine that built it."""

from __future__ import annotations

from pathlib import Path

import nbformat

from fnnbook.book import _copy_for_book


def _executed(tmp_path: Path, params: dict) -> Path:
    nb = nbformat.v4.new_notebook()
    src = "\n".join(f"{k} = {v!r}" for k, v in params.items())
    cell = nbformat.v4.new_code_cell(src, metadata={"tags": ["injected-parameters"]})
    cell.outputs = [nbformat.v4.new_output("stream", name="stdout", text=f"data in {params['data_dir']}\n")]
    nb.cells = [cell]
    nb.metadata["papermill"] = {"parameters": params}
    path = tmp_path / "task.ipynb"
    nbformat.write(nb, path)
    return path


def test_the_injected_paths_read_as_the_run_was_told(tmp_path: Path) -> None:
    root = tmp_path / "repo"
    out_root = tmp_path / "elsewhere" / "outputs"
    params = {"profile": "why", "data_dir": "../../../../../../work/shared/data",
              "out_dir": str(out_root / "why" / ".staging" / "123-abc" / "why_sec3"),
              "upstream_dirs": {"spiral": str(root / "outputs" / "paper" / "spiral"),
                                "theory": str(out_root / "paper" / "theory")},
              "note": "data"}
    dst = tmp_path / "page.ipynb"
    _copy_for_book(_executed(tmp_path, params), dst, root, out_dir=out_root / "why" / "why_sec3",
                   output_root=out_root)
    text = dst.read_text()
    assert str(tmp_path) not in text and "../../" not in text and ".staging" not in text
    page = nbformat.read(dst, as_version=4).cells[0]
    assert 'data_dir = \'DATA_DIR\'' in page.source and "data in DATA_DIR" in page.outputs[0]["text"]
    assert "<output root>/why/why_sec3" in page.source and "'outputs/paper/spiral'" in page.source
    assert "<output root>/paper/theory" in page.source and "note = 'data'" in page.source  # a bare word stays
