"""The runner, on tiny generated notebooks (each executes in about a second)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import papermill
import pytest
import yaml

from fnnbook import PipelineError, PipelineSpec, RunReport, load_spec, run
from fnnbook.runner import FINGERPRINT_FILE

from .nbfactory import MakePipeline, child_task, leaf_task


def _run(spec: PipelineSpec, tasks: list[str] | None = None, **kwargs: Any) -> tuple[RunReport, list[str]]:
    lines: list[str] = []
    report = run(spec, "smoke", tasks, progress_bar=False, echo=lines.append, **kwargs)
    return report, lines


def _set_leaf(pipeline: Path, **params: Any) -> PipelineSpec:
    doc = yaml.safe_load(pipeline.read_text())
    doc["tasks"]["leaf"]["parameters"]["smoke"].update(params)
    pipeline.write_text(yaml.safe_dump(doc, sort_keys=False))
    return load_spec(pipeline)


def test_run_skip_force_and_parameter_change(make_pipeline: MakePipeline) -> None:
    pipeline = make_pipeline()
    spec = load_spec(pipeline)
    out = spec.output_dir("smoke", "leaf")

    report, lines = _run(spec)
    assert report.ok and report.outcome("leaf").status == "ok"
    assert lines[0] == "[1/1] leaf ..."
    assert lines[1].startswith("[1/1] leaf ... ok (") and lines[1].endswith(" s)")
    assert lines[-1] == "profile smoke: 1 ok"
    results = json.loads((out / "results.json").read_text())
    assert results["claims"][0]["numbers"] == {"value": 2}
    assert (out / "leaf.ipynb").is_file() and (out / FINGERPRINT_FILE).is_file()
    assert not (spec.output_root / "smoke" / ".staging" / "leaf").exists()
    executed = (out / "leaf.ipynb").read_text()
    assert json.dumps(str(out))[1:-1] in executed and ".staging" not in executed  # final out_dir shown

    report, lines = _run(spec)  # unchanged: skipped
    assert report.outcome("leaf").status == "skipped"
    assert lines == ["[1/1] leaf ... skipped (up to date)", "profile smoke: 1 skipped"]

    stamp = (out / "leaf.ipynb").stat().st_mtime_ns
    report, _ = _run(spec, force=True)  # forced: reruns
    assert report.outcome("leaf").status == "ok"
    assert (out / "leaf.ipynb").stat().st_mtime_ns != stamp

    spec = _set_leaf(pipeline, value=5)  # changed parameter: reruns
    report, _ = _run(spec)
    assert report.outcome("leaf").status == "ok"
    assert (out / "value.txt").read_text() == "5.0"

    (out / "value.txt").unlink()  # a missing product: reruns
    report, _ = _run(spec)
    assert report.outcome("leaf").status == "ok"


def test_failure_keeps_last_good_output(make_pipeline: MakePipeline) -> None:
    pipeline = make_pipeline({"leaf": leaf_task(), "child": child_task()})
    spec = load_spec(pipeline)
    assert _run(spec)[0].ok
    out = spec.output_dir("smoke", "leaf")
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    spec = _set_leaf(pipeline, fail=True)
    report, lines = _run(spec, ["leaf", "child"])
    assert not report.ok
    assert report.outcome("leaf").status == "failed"
    assert report.outcome("leaf").message == "RuntimeError: boom: asked to fail"
    assert report.outcome("child").status == "not run"
    log = spec.output_root / "smoke" / "_logs" / "leaf.log"
    assert any(line.startswith("[1/2] leaf ... FAILED (see log ") and str(log) in line for line in lines)
    assert "[2/2] child ... not run (upstream leaf failed)" in lines
    assert f"  FAILED leaf: log {log}" in lines[-1]
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # untouched
    text = log.read_text()
    assert "RuntimeError" in text and "boom: asked to fail" in text
    assert (log.parent / "leaf.ipynb").is_file()  # the failed executed notebook beside the log
    assert not (spec.output_root / "smoke" / ".staging" / "leaf").exists()

    spec = _set_leaf(pipeline, fail=False, value=4)  # fixed (and changed): runs, and the stale failure notebook goes
    assert _run(spec, ["leaf"])[0].ok
    assert not (log.parent / "leaf.ipynb").exists()


def test_missing_product_is_a_failure(make_pipeline: MakePipeline) -> None:
    leaf = leaf_task()
    leaf["products"] = ["results.json", "model.pt"]
    spec = load_spec(make_pipeline({"leaf": leaf}))
    report, _ = _run(spec)
    assert report.outcome("leaf").status == "failed"
    assert "did not write these products: model.pt" in report.outcome("leaf").message
    assert not spec.output_dir("smoke", "leaf").exists()


def test_upstream_runs_first(make_pipeline: MakePipeline) -> None:
    spec = load_spec(make_pipeline({"leaf": leaf_task(), "child": child_task()}))
    report, lines = _run(spec, ["child"])
    assert [o.task for o in report.outcomes] == ["leaf", "child"]
    assert [o.status for o in report.outcomes] == ["ok", "ok"]
    assert (spec.output_dir("smoke", "child") / "double.txt").read_text() == "4.0"

    report, lines = _run(spec, ["child"], force=True)  # force applies to the named task only
    assert [o.status for o in report.outcomes] == ["skipped", "ok"]

    _run(spec, ["leaf"], force=True)  # a rerun upstream makes its children stale
    report, lines = _run(spec, ["child"])
    assert [o.status for o in report.outcomes] == ["skipped", "ok"]


def test_everything_is_checked_before_anything_runs(make_pipeline: MakePipeline) -> None:
    child = child_task()
    child["parameters"]["smoke"] = {"bogus": 1}
    spec = load_spec(make_pipeline({"leaf": leaf_task(), "child": child}))
    with pytest.raises(PipelineError, match=r"task 'child', profile 'smoke', parameter 'bogus'"):
        _run(spec)
    assert not spec.output_root.exists()


def test_interrupt_keeps_last_good_output(make_pipeline: MakePipeline,
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    spec = load_spec(make_pipeline())
    assert _run(spec)[0].ok
    out = spec.output_dir("smoke", "leaf")
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def interrupted(*args: Any, **kwargs: Any) -> None:
        Path(args[1]).write_text("{}")  # papermill has started writing the executed notebook
        raise KeyboardInterrupt

    monkeypatch.setattr(papermill, "execute_notebook", interrupted)
    lines: list[str] = []
    with pytest.raises(KeyboardInterrupt):
        run(spec, "smoke", force=True, progress_bar=False, echo=lines.append)
    assert any("FAILED (interrupted" in line for line in lines)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not (spec.output_root / "smoke" / ".staging" / "leaf").exists()
    assert "KeyboardInterrupt" in (spec.output_root / "smoke" / "_logs" / "leaf.log").read_text()


def test_interrupted_swap_is_recovered(make_pipeline: MakePipeline) -> None:
    spec = load_spec(make_pipeline())
    assert _run(spec)[0].ok
    out = spec.output_dir("smoke", "leaf")
    aside = spec.output_root / "smoke" / ".staging" / "1234-deadbeef" / "leaf.old"  # a killed run's
    aside.parent.mkdir(parents=True)
    out.rename(aside)  # as if the process died between the two renames
    report, _ = _run(spec)
    assert report.outcome("leaf").status == "skipped"
    assert out.is_dir() and not aside.exists()


def test_glob_product_matches_every_file_and_must_match_one(make_pipeline: MakePipeline) -> None:
    leaf = leaf_task()
    leaf["products"] = ["results.json", "value*.txt"]  # the leaf writes value.txt
    spec = load_spec(make_pipeline({"leaf": leaf}))
    report, _ = _run(spec)
    assert report.outcome("leaf").status == "ok"
    record = json.loads((spec.output_dir("smoke", "leaf") / FINGERPRINT_FILE).read_text())
    assert sorted(record["products"]) == ["results.json", "value.txt"]  # the pattern recorded as its files
    assert _run(spec)[0].outcome("leaf").status == "skipped"
    (spec.output_dir("smoke", "leaf") / "value.txt").unlink()  # a matched file gone: stale, runs again
    assert _run(spec)[0].outcome("leaf").status == "ok"

    leaf["products"] = ["results.json", "model_seed*.pt"]
    spec = load_spec(make_pipeline({"leaf": leaf}))
    report, _ = _run(spec, force=True)
    assert report.outcome("leaf").status == "failed"
    assert "did not write these products: model_seed*.pt" in report.outcome("leaf").message


def test_a_downstream_notebook_reads_what_its_upstream_ran_with(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    """upstream_parameters: the parameters of the upstream's last good run (profile overrides included)."""
    from fnnbook.params import upstream_parameters  # noqa: PLC0415

    spec = load_spec(make_pipeline({"leaf": leaf_task(value=7)}))
    with pytest.raises(PipelineError, match="no run record"):
        upstream_parameters(spec.output_dir("smoke", "leaf"))
    assert _run(spec)[0].ok
    ran = upstream_parameters(spec.output_dir("smoke", "leaf"))
    assert {k: ran[k] for k in ("value", "scale", "fail", "profile")} == {"value": 7, "scale": 1.0, "fail": False,
                                                                        "profile": "smoke"}
    assert "out_dir" not in ran  # no machine paths


def test_a_changed_claims_registry_is_read_again(tmp_path: Path) -> None:
    """The registry's claim IDs are cached by the file's content: an edit is seen at the next check, a broken
    registry is refused as before."""
    from fnnbook.runner import _known_claims  # noqa: PLC0415

    from .nbfactory import CLAIMS_YAML  # noqa: PLC0415

    claims = tmp_path / "claims.yaml"
    claims.write_text(CLAIMS_YAML)
    assert _known_claims(claims) == {"S1", "S2"}
    claims.write_text(CLAIMS_YAML.replace("id: S2", "id: S3"))
    assert _known_claims(claims) == {"S1", "S3"}
    claims.write_text(CLAIMS_YAML.replace("id: S2", "id: S1"))
    with pytest.raises(PipelineError, match="S1"):
        _known_claims(claims)
