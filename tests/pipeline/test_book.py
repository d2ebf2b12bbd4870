"""Assemble and build the book from fake outputs, with warnings as errors."""

from __future__ import annotations

import json
import shutil
import struct
import zlib
from base64 import b64encode
from pathlib import Path
from typing import Any

import nbformat
import pytest
import yaml

from fnnbook import PipelineError, PipelineSpec, load_spec
from fnnbook.book import GENERATED, assemble_book, build_book
from fnnbook.results import ClaimResult, write_results

REPO_BOOK = Path(__file__).resolve().parents[2] / "book"

CLAIMS = """groups:
  - name: Spiral (Sec. 3)
    settings: the spiral
    claims:
      - {id: S1, statement: the neural ODE fits the nominal dynamics (change rate), section: Sec. 3.1,
         figure: Fig. 4c, task: alpha}
      - {id: S2, statement: "feedback lowers the N=50 multi-step error; gamma/lambda_min(L)", section: Sec. 3.3,
         figure: Fig. 4d-f, task: beta}
  - name: Beyond the paper
    settings: ours
    claims:
      - {id: B1, statement: tune L and beta, section: Sec. 7, figure: none, task: alpha}
"""


def _png() -> bytes:
    """A valid 2x2 grey PNG, written by hand (no plotting library needed)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    raw = b"".join(b"\x00" + b"\x80\x80" for _ in range(2))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 2, 2, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def _executed_notebook(path: Path) -> None:
    """What papermill leaves: title, parameters, injected parameters, outputs (text, stderr, image)."""
    nb = nbformat.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    out_dir = str(path.parent)  # absolute, as the runner injects it
    nb.metadata["papermill"] = {"parameters": {"profile": "paper", "out_dir": out_dir,
                                               "upstream_dirs": {"up": out_dir + "-up"}}}
    nb.cells = [
        nbformat.v4.new_markdown_cell("# Linear feedback on the spiral\n\n"
                                      "Reproduces Fig. 4 ($L_i = L e^{-\\beta i}$)."),
        nbformat.v4.new_code_cell('profile = "paper"\nout_dir = "."', metadata={"tags": ["parameters"]}),
        nbformat.v4.new_code_cell(f'profile = "paper"\nout_dir = "{out_dir}"\nupstream_dirs = {{"up": "{out_dir}-up"}}',
                                  metadata={"tags": ["injected-parameters"]}),
        nbformat.v4.new_markdown_cell("## Results"),
        nbformat.v4.new_code_cell("print(1)", execution_count=3, outputs=[
            nbformat.v4.new_output("stream", name="stdout", text=f"wrote {out_dir}/results.json\n"),
            nbformat.v4.new_output("stream", name="stderr", text="a warning\n"),
            nbformat.v4.new_output("display_data", data={"image/png": b64encode(_png()).decode(),
                                                         "text/plain": "<Figure>"}),
        ]),
        nbformat.v4.new_code_cell("\n".join(f"x{i} = {i}" for i in range(20))),  # long: folded
        nbformat.v4.new_code_cell("y = 1"),  # short, no figure: stays open
        nbformat.v4.new_code_cell("\n".join(f"z{i} = {i}" for i in range(20)), metadata={"tags": ["show-input"]}),
    ]
    nbformat.write(nb, path)


@pytest.fixture
def fake_outputs(tmp_path: Path) -> PipelineSpec:
    """A two-part pipeline where only task `alpha` has (paper-profile) outputs."""
    for name in ("alpha", "beta"):
        nb = nbformat.v4.new_notebook()
        nb.cells = [nbformat.v4.new_code_cell('profile = ""\nout_dir = ""',
                                              metadata={"tags": ["parameters"]})]
        (tmp_path / "notebooks").mkdir(exist_ok=True)
        nbformat.write(nb, tmp_path / "notebooks" / f"{name}.ipynb")
    (tmp_path / "claims.yaml").write_text(CLAIMS)
    task = {"notebook": "", "upstream": [], "products": ["results.json"], "parameters": {"paper": {}}}
    doc = {"claims_file": "claims.yaml", "output_root": "outputs",
           "parts": [{"title": "Linear feedback (Sec. 3)", "tasks": ["alpha"]},
                     {"title": "Neural feedback (Sec. 4)", "tasks": ["beta"]}],
           "tasks": {"alpha": {**task, "title": "Alpha", "notebook": "notebooks/alpha.ipynb",
                               "claims": ["S1"]},
                     "beta": {**task, "title": "Beta", "notebook": "notebooks/beta.ipynb",
                              "claims": ["S2"]}}}
    (tmp_path / "pipeline.yaml").write_text(yaml.safe_dump(doc))
    spec = load_spec(tmp_path / "pipeline.yaml")

    out = spec.output_dir("paper", "alpha")
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "fig4c.png").write_bytes(_png())
    _executed_notebook(out / "alpha.ipynb")
    write_results(out, task="alpha", profile="paper", claims=[
        ClaimResult("S1", checks={"error below 0.1": True}, numbers={"rmse": 0.0421, "n": 1000},
                    rule="rmse < 0.1", figure="figures/fig4c.png")])
    return spec


def _copy_book(tmp_path: Path) -> Path:
    book = tmp_path / "book"
    shutil.copytree(REPO_BOOK, book, ignore=shutil.ignore_patterns("_build", "_generated", "_toc.yml"))
    return book


def test_assemble_and_build_with_warnings_as_errors(fake_outputs: PipelineSpec, tmp_path: Path) -> None:
    book = _copy_book(tmp_path)
    toc = yaml.safe_load(assemble_book(fake_outputs, "paper", book, api=False).read_text())  # API: tests/reader
    assert toc["root"] == "intro"
    assert [p["caption"] for p in toc["parts"]] == ["Linear feedback (Sec. 3)", "Neural feedback (Sec. 4)", "Results"]
    assert toc["parts"][0]["chapters"] == [{"file": "_generated/alpha/alpha"}]
    assert toc["parts"][1]["chapters"] == [{"file": "_generated/beta/beta"}]  # no output: a page that says so
    assert "fnn-pipeline run --profile paper beta" in (book / "_generated" / "beta" / "beta.md").read_text()
    assert toc["parts"][2]["chapters"] == [{"file": "_generated/scoreboard"}, {"file": "paper_vs_release"}]
    assert (book / "_generated" / "alpha" / "figures" / "fig4c.png").is_file()
    scoreboard = (book / "_generated" / "scoreboard.md").read_text()
    assert ("3 claims, 1 reproduced, 0 partly, 0 not reproduced, "
            "0 better than claimed, 0 verified by construction, 2 not run.") in scoreboard
    assert (book / "_generated" / "verdicts.png").read_bytes()[:4] == b"\x89PNG"

    copied = nbformat.read(book / "_generated" / "alpha" / "alpha.ipynb", as_version=4)
    assert str(fake_outputs.root) not in nbformat.writes(copied)  # no path of the machine that ran it
    assert copied.cells[2].source == ('profile = "paper"\nout_dir = "outputs/paper/alpha"\n'
                                      'upstream_dirs = {"up": "outputs/paper/alpha-up"}')
    assert copied.cells[4].outputs[0]["text"] == "wrote outputs/paper/alpha/results.json\n"
    tags = [c.metadata.get("tags", []) for c in copied.cells]
    assert "remove-cell" in tags[1] and "hide-input" not in tags[2]  # defaults gone, the run's values open
    assert "hide-input" in tags[4] and "hide-input" in tags[5]  # draws a figure; longer than FOLD_LINES
    assert tags[6] == [] and tags[7] == ["show-input"]  # short; the author keeps it open

    html = build_book(book, quiet=True)
    assert (html / "intro.html").is_file() and (html / "paper_vs_release.html").is_file()
    assert (html / "_generated" / "alpha" / "alpha.html").is_file()
    page = (html / "_generated" / "scoreboard.html").read_text()
    assert "sd-bg-success" in page and "reproduced" in page and "not run" in page
    assert "alpha.html" in page and "fig4c.png" in page and "verdicts.png" in page
    assert (html / "_static" / "mathjax" / "tex-chtml.js").is_file()  # MathJax ships with the book
    for built in html.rglob("*.html"):
        text = built.read_text()
        assert "cdn.jsdelivr" not in text and "unpkg.com" not in text, f"{built} names a web script"
    alpha = (html / "_generated" / "alpha" / "alpha.html").read_text()
    assert 'src="../../_static/mathjax/tex-chtml.js' in alpha and "a warning" not in alpha  # stderr dropped

    with (book / "intro.md").open("a") as fh:  # a broken link is a warning, hence an error
        fh.write("\nSee [nothing](missing-page.md).\n")
    with pytest.raises(PipelineError, match="book build failed"):
        build_book(book, quiet=True)


def test_assemble_needs_the_hand_written_pages(fake_outputs: PipelineSpec, tmp_path: Path) -> None:
    book = _copy_book(tmp_path)
    (book / "paper_vs_release.md").unlink()
    with pytest.raises(PipelineError, match="paper_vs_release.md is missing"):
        assemble_book(fake_outputs, "paper", book)


def test_build_needs_an_assembled_book(tmp_path: Path) -> None:
    with pytest.raises(PipelineError, match="has no _toc.yml; run assemble_book first"):
        build_book(tmp_path)


def test_a_long_text_output_scrolls_and_a_short_one_does_not() -> None:
    """Per-seed dumps get a scrolling box in the book (scroll-output); a few lines stay as they are."""
    import nbformat  # noqa: PLC0415

    from fnnbook.book import SCROLL_LINES, _fold  # noqa: PLC0415

    def cell(lines: int) -> nbformat.NotebookNode:
        text = "\n".join(str(i) for i in range(lines))
        return nbformat.v4.new_code_cell("x", outputs=[nbformat.v4.new_output(
            "execute_result", data={"text/plain": text}, execution_count=1)])

    long, short = cell(SCROLL_LINES + 5), cell(3)
    _fold(long)
    _fold(short)
    assert "scroll-output" in long.metadata["tags"]
    assert "scroll-output" not in short.metadata.get("tags", [])


@pytest.mark.parametrize(("damage", "said"), [
    ("delete", "not in this output root"), ("notebook", "executed notebook alpha.ipynb is missing"),
    ("truncate", "results.json cannot be read"), ("hashed", "results.json is truncated or changed")])
def test_a_damaged_task_gets_a_page_and_the_good_book_stays(fake_outputs: PipelineSpec, tmp_path: Path,
                                                            damage: str, said: str) -> None:
    book = _copy_book(tmp_path)
    assemble_book(fake_outputs, "paper", book)
    good = sorted(p.relative_to(book) for p in (book / GENERATED).rglob("*"))
    out = fake_outputs.output_dir("paper", "alpha")
    if damage == "delete":
        shutil.rmtree(out)
    elif damage == "notebook":
        (out / "alpha.ipynb").unlink()
    elif damage == "hashed":  # the run record's hash no longer matches
        (out / ".fingerprint.json").write_text(json.dumps({"products": {"results.json": "0" * 64}}))
    else:
        (out / "results.json").write_text((out / "results.json").read_text()[:40])
    assemble_book(fake_outputs, "paper", book)
    page = (book / GENERATED / "alpha" / "alpha.md").read_text()
    assert "Not run: " in page and "fnn-pipeline run --profile paper alpha" in page
    assert said.split()[-1] in page
    assert "not run: " in (book / GENERATED / "scoreboard.md").read_text()
    assert good and not (book / f"{GENERATED}.new").exists()


def test_a_failing_assembly_leaves_the_good_book(fake_outputs: PipelineSpec, tmp_path: Path,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    book = _copy_book(tmp_path)
    assemble_book(fake_outputs, "paper", book)
    before = (book / GENERATED / "scoreboard.md").read_text()
    import fnnbook.book as book_module

    def broken(*args: object, **kwargs: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(book_module, "plot_verdicts", broken)
    with pytest.raises(OSError):
        assemble_book(fake_outputs, "paper", book)
    assert (book / GENERATED / "scoreboard.md").read_text() == before
    assert (book / GENERATED / "alpha" / "alpha.ipynb").is_file()
    assert not (book / f"{GENERATED}.new").exists()


def _with_why_task(spec: PipelineSpec) -> PipelineSpec:
    """fake_outputs plus a why task of the `why` profile (extending paper) that explains S1."""
    doc = yaml.safe_load(spec.path.read_text())
    nbformat.write(nbformat.read(spec.root / "notebooks" / "alpha.ipynb", as_version=4),
                   spec.root / "notebooks" / "why_alpha.ipynb")
    doc["profiles"] = {"why": {"extends": "paper"}}
    doc["tasks"]["why_alpha"] = {"title": "Why alpha", "notebook": "notebooks/why_alpha.ipynb", "claims": [],
                                 "explains": ["S1"], "upstream": ["alpha"], "products": ["whys.json"],
                                 "parameters": {"why": {}}}
    doc["parts"].append({"title": "Why each claim stands where it stands", "tasks": ["why_alpha"]})
    spec.path.write_text(yaml.safe_dump(doc))
    return load_spec(spec.path)


def test_the_why_rows_read_not_run_then_the_runs_summary(fake_outputs: PipelineSpec, tmp_path: Path) -> None:
    import numpy as np  # noqa: PLC0415

    from fnnbook.why import Axis, Why, WhyGrid, write_whys  # noqa: PLC0415

    spec = _with_why_task(fake_outputs)
    book = _copy_book(tmp_path)
    toc = yaml.safe_load(assemble_book(spec, "paper", book, api=False).read_text())
    assert "Why each claim stands where it stands" not in [p["caption"] for p in toc["parts"]]  # not run: no page
    board = (book / "_generated" / "scoreboard.md").read_text()
    assert "**Why.** not run (`make why`)" in board and "*why: not run*" in board

    out = spec.output_dir("why", "why_alpha")
    out.mkdir(parents=True)
    _executed_notebook(out / "why_alpha.ipynb")
    grid = WhyGrid(axes=(Axis("noise_std", (0.001, 0.01), "the noise level is not given", ours=0.01),),
                   holds=np.array([True, False]), n=5, rule="S1's rule")
    write_whys(out, [Why("S1", "partly", grids=(grid,))])
    toc = yaml.safe_load(assemble_book(spec, "paper", book, api=False).read_text())
    assert toc["parts"][2] == {"caption": "Why each claim stands where it stands", "numbered": True,
                               "chapters": [{"file": "_generated/why_alpha/why_alpha"}]}
    board = (book / "_generated" / "scoreboard.md").read_text()
    assert ("**Why.** holds for noise\\_std \\<= 0.001, fails at 0.01 and above (5 seeds per point) "
            "([the runs](why_alpha/why_alpha.ipynb))") in board
    assert "*(b) a setting the paper leaves open:*" in board and "*why: (b)*" in board
    html = build_book(book, quiet=True)
    assert "holds for noise_std &lt;= 0.001, fails at 0.01 and above" in (html / "_generated" / "scoreboard.html").read_text()


def test_two_builds_side_by_side_on_one_book_folder(fake_outputs: PipelineSpec, tmp_path: Path) -> None:
    """Two builds of one book folder from two output roots, 0.5 s apart: both succeed, one after the other
    (the folder's lock), each in a scratch folder of its own; the book left shows one root's pages only, and
    records which root and profile it shows. (Before, both used ``_generated.new``: both failed, or one book
    showed the other root's verdicts.)"""
    import threading  # noqa: PLC0415
    import time  # noqa: PLC0415

    from fnnbook.book import SHOWN_FILE, make_book  # noqa: PLC0415

    other = fake_outputs.with_paths(output_root=tmp_path / "other")
    shutil.copytree(fake_outputs.output_root, other.output_root)
    write_results(other.output_dir("paper", "alpha"), task="alpha", profile="paper", claims=[
        ClaimResult("S1", checks={"error below 0.1": False}, numbers={"rmse": 0.5, "n": 1000}, rule="rmse < 0.1",
                    figure="figures/fig4c.png")])
    book = _copy_book(tmp_path)
    said: dict[str, list[str]] = {"outputs": [], "other": []}
    finished: list[str] = []
    errors: list[BaseException] = []

    def build(spec: PipelineSpec, name: str) -> None:
        try:
            make_book(spec, "paper", book, api=False, quiet=True, echo=said[name].append)
            finished.append(name)
        except BaseException as exc:  # noqa: BLE001 (reported below)
            errors.append(exc)

    threads = [threading.Thread(target=build, args=(fake_outputs, "outputs")),
               threading.Thread(target=build, args=(other, "other"))]
    threads[0].start()
    time.sleep(0.5)
    threads[1].start()
    for t in threads:
        t.join(timeout=600)
    assert not errors and sorted(finished) == ["other", "outputs"]
    assert any("waiting for another book build" in line for line in said[finished[1]])
    last = finished[1]
    shown = json.loads((book / GENERATED / SHOWN_FILE).read_text())
    assert shown == {"profile": "paper", "output_root": last}
    scoreboard = (book / GENERATED / "scoreboard.md").read_text()
    assert ("1 reproduced, 0 partly, 0 not reproduced" in scoreboard) == (last == "outputs")
    assert ("0 reproduced, 0 partly, 1 not reproduced" in scoreboard) == (last == "other")
    page = (book / "_build" / "html" / "_generated" / "scoreboard.html").read_text()
    assert f"output root <code class=\"docutils literal notranslate\"><span class=\"pre\">{last}</span>" in page
    assert not [p.name for p in book.iterdir() if p.name.startswith((".build-", "_generated."))]  # no scratch left


def test_a_stale_claim_is_said_with_the_command_that_refreshes_it(make_pipeline: Any, tmp_path: Path) -> None:
    """A task rerun would change (here its parameter): the scoreboard marks its claims stale, never current."""
    from fnnbook import run  # noqa: PLC0415

    from .nbfactory import child_task, leaf_task  # noqa: PLC0415

    pipeline = make_pipeline({"leaf": leaf_task(), "child": child_task()})
    spec = load_spec(pipeline)
    assert run(spec, "smoke", progress_bar=False, echo=lambda _: None).ok
    book = _copy_book(tmp_path)
    assemble_book(spec, "smoke", book, api=False)
    board = (book / "_generated" / "scoreboard.md").read_text()
    assert "stale" not in board.lower()
    doc = yaml.safe_load(pipeline.read_text())
    doc["tasks"]["leaf"]["parameters"]["smoke"]["value"] = 7  # the run's input changed: its result is stale
    pipeline.write_text(yaml.safe_dump(doc, sort_keys=False))
    spec = load_spec(pipeline)
    assemble_book(spec, "smoke", book, api=False)
    board = (book / "_generated" / "scoreboard.md").read_text()
    assert "`reproduced` *stale*" in board
    assert "**Stale.** This verdict comes from outputs whose inputs changed since they ran; " \
           "`fnn-pipeline run --profile smoke leaf` refreshes it." in board
    assert "2 row(s) show results that are **stale**" not in board and "1 row(s) show results that are **stale**" in board
