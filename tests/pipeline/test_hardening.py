"""Runner hardening: product hashes, relocatable outputs, data hashes, notebook checks, missing data, kills."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from fnnbook import PipelineError, check, is_up_to_date, load_spec, run
from fnnbook.book import assemble_book
from fnnbook.runner import mark_killed

from .nbfactory import MakePipeline, book_parameters_cell, child_task, leaf_task, write_notebook

REPO = Path(__file__).resolve().parents[2]


def _quiet(spec, tasks=None, **kw):  # type: ignore[no-untyped-def]
    return run(spec, "smoke", tasks, progress_bar=False, echo=lambda _: None, **kw)


def test_corrupt_product_is_stale_and_copied_tree_is_not(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    spec = load_spec(make_pipeline({"leaf": leaf_task(), "child": child_task()}))
    assert _quiet(spec).ok
    plan = check(spec, "smoke")
    assert is_up_to_date(spec, plan, "leaf") and is_up_to_date(spec, plan, "child")

    # the whole output tree moved to another root: still up to date (no absolute path in a fingerprint)
    shutil.copytree(spec.output_root, tmp_path / "copy")
    moved = spec.with_paths(output_root=tmp_path / "copy")
    plan_moved = check(moved, "smoke")
    assert is_up_to_date(moved, plan_moved, "leaf") and is_up_to_date(moved, plan_moved, "child")

    # a truncated product: stale, and rerun
    value = spec.output_dir("smoke", "leaf") / "value.txt"
    value.write_text("")
    assert not is_up_to_date(spec, plan, "leaf")
    report = _quiet(spec)
    assert [o.status for o in report.outcomes] == ["ok", "ok"]
    assert value.read_text() == "2.0"


def test_data_files_enter_the_fingerprint_not_the_data_path(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb",
                   'profile = ""\nout_dir = ""\ndata_dir = ""\nvalue = 1\n', "pass")
    spec = load_spec(make_pipeline({"leaf": {**leaf_task(), "products": []}}))
    for folder in ("data", "elsewhere"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "throws.bin").write_bytes(b"abc")
    (tmp_path / "data" / "README.md").write_text("only in the repository's folder")
    here = check(spec, "smoke").fingerprints["leaf"]
    there = check(spec.with_paths(data_dir=tmp_path / "elsewhere"), "smoke").fingerprints["leaf"]
    assert here == there
    (tmp_path / "elsewhere" / "throws.bin").write_bytes(b"abd")
    assert check(spec.with_paths(data_dir=tmp_path / "elsewhere"), "smoke").fingerprints["leaf"] != here


@pytest.mark.parametrize(("name", "value", "message"), [
    ("L", -1.0, "not positive definite"),
    ("L", 250.0, "unstable"),
    ("N", 0, "N"),
    ("iterations", 0, "iterations must be an integer >= 1"),
    ("seeds", [0], "seeds must list at least 2 distinct integers"),
    ("seeds", [1, 1], "seeds must list at least 2 distinct integers"),
    ("noise_std", 0.03, "noise_sweep must hold 0 and the judged level"),
])
def test_notebook_value_checks_run_before_anything(name: str, value: object, message: str,
                                                   tmp_path: Path) -> None:
    """The real spiral notebook's checks (fnnbook.tasks.spiral.SpiralSettings), on a copy of pipeline.yaml."""
    doc = yaml.safe_load((REPO / "pipeline.yaml").read_text())
    doc["claims_file"] = str(REPO / "claims.yaml")
    for task in doc["tasks"].values():
        task["notebook"] = str(REPO / task["notebook"])
        task["claims"] = []
    doc["tasks"]["spiral"]["parameters"]["smoke"][name] = value
    (tmp_path / "data").mkdir()
    (tmp_path / "pipeline.yaml").write_text(yaml.safe_dump(doc))
    spec = load_spec(tmp_path / "pipeline.yaml")
    with pytest.raises(PipelineError, match=rf"task 'spiral', profile 'smoke': .*{message}"):
        check(spec, "smoke", ["ablations"])  # the error is upstream's, found before anything runs
    assert not (tmp_path / "outputs").exists()


@pytest.mark.parametrize(("task", "name", "value", "message"), [
    ("bottle", "N", 0, "N must be an integer >= 1"),
    ("quadrotor_mpc", "u_max_judged", 5.0, "u_max_judged = 5.0 must be one of u_max"),
    ("own_system", "tune_iterations", 60, "tune_iterations and spiral_tune_iterations must equal"),
    ("cascaded_tanks", "series_N", 7, "series_N = 7 must be one of horizons"),
    ("why_sec3", "s3_noise", [0.003, 0.03], "noise_std = 0.01 in s3_noise"),
    ("quick_start", "T", 300.5, "parameter 'T': got float 300.5, but the notebook's default is int"),
    ("theory", "Lsweep", [1.0], r"parameter 'Lsweep': not declared in 02_theory.ipynb's settings "
                                r"\(fnnbook.tasks.theory\); did you mean 'L_sweep'"),
])
def test_a_bad_value_in_pipeline_yaml_is_refused_before_any_work(task: str, name: str, value: object, message: str,
                                                                  tmp_path: Path) -> None:
    """Each task's settings dataclass checks its profile's values (type, value, the values between them) when the
    run starts: the error names task, profile and parameter, and nothing has run."""
    doc = yaml.safe_load((REPO / "pipeline.yaml").read_text())
    doc["claims_file"] = str(REPO / "claims.yaml")
    for t in doc["tasks"].values():
        t["notebook"] = str(REPO / t["notebook"])
        t["claims"] = []
    doc["tasks"][task]["parameters"]["smoke"][name] = value
    (tmp_path / "data").mkdir()
    (tmp_path / "pipeline.yaml").write_text(yaml.safe_dump(doc))
    spec = load_spec(tmp_path / "pipeline.yaml")
    with pytest.raises(PipelineError, match=rf"task '{task}', profile 'smoke'.*{message}"):
        run(spec, "smoke", [task], progress_bar=False, echo=lambda _: None)
    assert not (tmp_path / "outputs").exists()


def test_missing_data_is_not_run_and_the_book_says_so(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "bottle.ipynb", book_parameters_cell("06_bottle"),
                   'from fnnbook.tasks.bottle import BottleSettings\n'
                   'BottleSettings.from_namespace(globals())\nraise RuntimeError("must not run")')
    bottle = {"title": "Bottle", "notebook": "notebooks/bottle.ipynb", "claims": ["S2"], "products": [],
              "parameters": {"smoke": {}}}
    after = {**child_task(), "upstream": ["bottle"]}
    write_notebook(tmp_path / "notebooks" / "child.ipynb", 'profile = ""\nout_dir = ""\nupstream_dirs = {}\n', "")
    spec = load_spec(make_pipeline({"leaf": leaf_task(), "bottle": bottle, "after": after}))
    (tmp_path / "data").mkdir()
    lines: list[str] = []
    report = run(spec, "smoke", progress_bar=False, echo=lines.append)
    assert report.ok  # missing data is not a failure
    assert [report.outcome(t).status for t in ("leaf", "bottle", "after")] == ["ok", "not run", "not run"]
    assert report.outcome("bottle").message.startswith("data missing: Training_dataset.mat")
    assert "fnn-pipeline data fetch" in report.outcome("bottle").message
    summary = lines[-1].splitlines()
    assert summary[0] == "profile smoke: 1 ok, 2 not run"
    assert summary[1].startswith("  NOT RUN bottle: data missing")
    assert summary[2] == "  NOT RUN after: upstream bottle did not run (data missing)"

    book = tmp_path / "book"
    book.mkdir()
    for page in ("intro.md", "paper_vs_release.md", "_config.yml"):
        (book / page).write_text("# page\n" if page.endswith(".md") else "title: t\n")
    assemble_book(spec, "smoke", book)
    page = (book / "_generated" / "bottle" / "bottle.md").read_text()
    assert "Not run: data missing" in page and "fnn-pipeline data fetch" in page
    scoreboard = (book / "_generated" / "scoreboard.md").read_text()
    assert "not run: data missing" in scoreboard
    toc = yaml.safe_load((book / "_toc.yml").read_text())
    assert {"file": "_generated/bottle/bottle"} in toc["parts"][0]["chapters"]


def test_log_of_a_killed_attempt_gets_a_failed_marker(tmp_path: Path) -> None:
    log = tmp_path / "t.log"
    log.write_text("task: t\n\n--- kernel output ---\nhalf")
    mark_killed(log, "killed")
    assert log.read_text().endswith("half\n--- FAILED: killed ---\n")
    mark_killed(log, "again")  # an ended log is left alone
    assert log.read_text().count("FAILED") == 1


@pytest.mark.parametrize("threads", [1, 2])
def test_kernel_gets_the_torch_threads_asked_for(make_pipeline: MakePipeline, tmp_path: Path, threads: int) -> None:
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb", 'profile = ""\nout_dir = ""\n',
                   "import pathlib, torch\n(pathlib.Path(out_dir) / 'threads.txt').write_text(str(torch.get_num_threads()))")
    spec = load_spec(make_pipeline({"leaf": {**leaf_task(), "products": ["threads.txt"],
                                             "parameters": {"smoke": {}}}}))
    assert _quiet(spec, threads=threads).ok
    assert (spec.output_dir("smoke", "leaf") / "threads.txt").read_text() == str(threads)
    assert f"torch threads: {threads}" in (spec.output_root / "smoke" / "_logs" / "leaf.log").read_text()


def test_a_kernel_that_never_imports_torch_does_not_load_it(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    """The threads are set by an import hook, so a notebook without torch starts without it (and quickly)."""
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb", 'profile = ""\nout_dir = ""\n',
                   "import pathlib, sys\n(pathlib.Path(out_dir) / 'threads.txt').write_text(str('torch' in sys.modules))")
    spec = load_spec(make_pipeline({"leaf": {**leaf_task(), "products": ["threads.txt"],
                                             "parameters": {"smoke": {}}}}))
    assert _quiet(spec, threads=1).ok
    assert (spec.output_dir("smoke", "leaf") / "threads.txt").read_text() == "False"
