"""The parameters cell and the checks on each task's parameters."""

from __future__ import annotations

from pathlib import Path

import nbformat
import pytest
from .nbfactory import MakePipeline, book_parameters_cell, child_task, leaf_task, write_notebook

from fnnbook import PipelineError, PipelineSpec, check, load_spec, read_parameters
from fnnbook.params import _type_ok

PARAMS = (
    'profile = "smoke"\n'
    'out_dir = "."  # injected\n'
    "seed: int = 0\n"
    "L = 20.0\n"
    "hidden = [50, 50]\n"
    "adjoint = True\n"
    "method = 'dopri5'\n"
    "extra = None\n"
    "gains = {'a': 1}\n"
    "offset = -1.5\n"
)


def test_reads_literal_defaults_in_order(tmp_path: Path) -> None:
    nb = write_notebook(tmp_path / "a.ipynb", PARAMS, "print(seed)")
    got = read_parameters(nb)
    assert got == {"profile": "smoke", "out_dir": ".", "seed": 0, "L": 20.0, "hidden": [50, 50],
                   "adjoint": True, "method": "dopri5", "extra": None, "gains": {"a": 1}, "offset": -1.5}
    assert list(got) == ["profile", "out_dir", "seed", "L", "hidden", "adjoint", "method", "extra",
                         "gains", "offset"]


@pytest.mark.parametrize(("source", "message"), [
    ("import numpy as np\nseed = 0\n", r"only `name = literal` lines; line 1 is `import numpy as np`"),
    ("seed = 0\nprint(seed)\n", r"line 2 is `print\(seed\)`"),
    ("a = b = 1\n", r"line 1 is `a = b = 1`"),
    ("x, y = 1, 2\n", r"line 1"),
    ("n = 2 ** 10\n", r"parameter 'n' \(line 1\) is not a literal: `2 \*\* 10`"),
    ("path = str(1)\n", r"parameter 'path' \(line 1\) is not a literal"),
    ("seed = 0\nseed = 1\n", r"parameter 'seed' is assigned twice"),
    ("%matplotlib inline\nseed = 0\n", r"the parameters cell is not plain Python"),
])
def test_non_literal_parameters_cell_is_an_error(tmp_path: Path, source: str, message: str) -> None:
    nb = write_notebook(tmp_path / "bad.ipynb", source)
    with pytest.raises(PipelineError, match=message):
        read_parameters(nb)


def test_missing_parameters_cell_is_an_error(tmp_path: Path) -> None:
    nb = write_notebook(tmp_path / "none.ipynb", "seed = 0\n", tag="other")
    with pytest.raises(PipelineError, match=r"none.ipynb: no code cell is tagged 'parameters'"):
        read_parameters(nb)


def test_two_parameters_cells_are_an_error(tmp_path: Path) -> None:
    nb = write_notebook(tmp_path / "two.ipynb", "seed = 0\n", "seed = 1\n")
    doc = nbformat.read(nb, as_version=4)
    doc.cells[2].metadata["tags"] = ["parameters"]
    nbformat.write(doc, nb)
    with pytest.raises(PipelineError, match=r"2 cells are tagged 'parameters'"):
        read_parameters(nb)


def test_not_a_notebook_is_an_error(tmp_path: Path) -> None:
    bad = tmp_path / "x.ipynb"
    bad.write_text("not json")
    with pytest.raises(PipelineError, match="cannot be read as JSON"):
        read_parameters(bad)


@pytest.mark.parametrize(("default", "value", "ok"), [
    (1.0, 2, True), (1.0, 2.5, True), (1.0, True, False), (1, 2, True), (1, 2.0, False),
    (1, False, False), (True, False, True), (True, 1, False), ([1], [2, 3], True), ([1], 1, False),
    ("a", "b", True), ("a", 1, False), (None, [1], True), (None, "x", True), ({"a": 1}, {}, True),
    ({"a": 1}, [], False), ((1, 2), [3, 4], True),
    ([16, 16], [16, "a"], False), ([16, 16], [16, 16.7], False), ([1.0], [1, 2.5], True), ([], ["a"], True),
    ([[1.0, 2.0]], [[1, 2], [3.5]], True), ([[1.0, 2.0]], [[1, "x"]], False), (["a"], [], True),
])
def test_type_rule(default: object, value: object, ok: bool) -> None:
    assert _type_ok(default, value) is ok


def _spec_with_leaf_params(make_pipeline: MakePipeline, **params: object) -> PipelineSpec:
    return load_spec(make_pipeline({"leaf": leaf_task(**params)}))


def test_unknown_parameter_suggests_close_match(make_pipeline: MakePipeline) -> None:
    spec = _spec_with_leaf_params(make_pipeline, valeu=3)
    with pytest.raises(PipelineError, match=r"task 'leaf', profile 'smoke', parameter 'valeu': not "
                                            r"declared in the parameters cell of leaf.ipynb; did you "
                                            r"mean 'value'"):
        check(spec, "smoke")


def test_unknown_parameter_without_close_match(make_pipeline: MakePipeline) -> None:
    spec = _spec_with_leaf_params(make_pipeline, zzz=3)
    with pytest.raises(PipelineError, match=r"parameter 'zzz': not declared in the parameters cell "
                                            r"of leaf.ipynb$"):
        check(spec, "smoke")


@pytest.mark.parametrize(("name", "value", "message"), [
    ("value", 1.5, r"parameter 'value': got float 1.5, but the notebook's default is int 1"),
    ("value", True, r"parameter 'value': got bool True, but the notebook's default is int 1"),
    ("fail", 0, r"parameter 'fail': got int 0, but the notebook's default is bool False"),
    ("scale", "2", r"parameter 'scale': got str '2', but the notebook's default is float 1.0"),
    ("scale", [1.0], r"parameter 'scale': got list \[1.0\]"),
])
def test_wrong_type_is_an_error(make_pipeline: MakePipeline, name: str, value: object, message: str) -> None:
    spec = _spec_with_leaf_params(make_pipeline, **{name: value})
    with pytest.raises(PipelineError, match=r"task 'leaf', profile 'smoke', " + message):
        check(spec, "smoke")


def test_int_accepted_for_float_default(make_pipeline: MakePipeline) -> None:
    spec = _spec_with_leaf_params(make_pipeline, scale=2)
    plan = check(spec, "smoke")
    assert plan.parameters["leaf"]["scale"] == 2


@pytest.mark.parametrize("name", ["profile", "out_dir", "data_dir", "upstream_dirs"])
def test_task_may_not_set_injected_names(make_pipeline: MakePipeline, name: str) -> None:
    spec = _spec_with_leaf_params(make_pipeline, **{name: "x"})
    with pytest.raises(PipelineError, match=rf"parameter '{name}': '{name}' is injected by the runner"):
        check(spec, "smoke")


def test_upstream_needs_upstream_dirs(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "child.ipynb", 'profile = ""\nout_dir = ""\n', "pass")
    spec = load_spec(make_pipeline({"leaf": leaf_task(), "child": child_task()}))
    with pytest.raises(PipelineError, match=r"task 'child' has upstream tasks \(leaf\) but notebook "
                                            r"child.ipynb does not declare 'upstream_dirs'"):
        check(spec, "smoke", ["child"])


def test_notebook_must_declare_out_dir(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb", 'profile = ""\nvalue = 1\n', "pass")
    spec = load_spec(make_pipeline())
    with pytest.raises(PipelineError, match=r"notebook leaf.ipynb must declare 'out_dir'"):
        check(spec, "smoke")


def test_missing_profile_is_an_error(make_pipeline: MakePipeline) -> None:
    task = leaf_task()
    del task["parameters"]["paper"]
    spec = load_spec(make_pipeline({"leaf": task, "child": child_task()}))
    with pytest.raises(PipelineError, match=r"task 'leaf' has no parameters for profile 'paper'"):
        check(spec, "paper")
    with pytest.raises(PipelineError, match=r"unknown profile 'papr'; profiles: paper, smoke"):
        check(spec, "papr")


def test_every_default_is_injected_and_overrides_win(make_pipeline: MakePipeline) -> None:
    spec = load_spec(make_pipeline({"leaf": leaf_task(scale=2)}))
    paper = check(spec, "paper").parameters["leaf"]
    assert {k: paper[k] for k in ("value", "scale", "fail")} == {"value": 3, "scale": 1.0, "fail": False}
    smoke = check(spec, "smoke").parameters["leaf"]
    assert {k: smoke[k] for k in ("value", "scale", "fail")} == {"value": 2, "scale": 2, "fail": False}


def test_list_elements_are_checked(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb", 'profile = ""\nout_dir = ""\nhidden = [16, 16]\n', "pass")
    for bad in ([16, "a"], [16, 16.7]):
        spec = load_spec(make_pipeline({"leaf": {**leaf_task(), "parameters": {"smoke": {"hidden": bad}}}}))
        with pytest.raises(PipelineError, match=r"parameter 'hidden': got list"):
            check(spec, "smoke")


def test_resolved_parameters_inject_paths(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "child.ipynb",
                   'profile = ""\nout_dir = ""\nupstream_dirs = {}\ndata_dir = ""\n', "pass")
    (tmp_path / "data").mkdir()
    spec = load_spec(make_pipeline({"leaf": leaf_task(), "child": child_task()}))
    plan = check(spec, "smoke", ["child"])
    assert plan.order == ("leaf", "child")
    params = plan.parameters["child"]
    assert params["profile"] == "smoke"
    assert params["out_dir"] == str(tmp_path / "outputs" / "smoke" / ".staging" / plan.run / "child")
    assert params["upstream_dirs"] == {"leaf": str(tmp_path / "outputs" / "smoke" / "leaf")}
    assert params["data_dir"] == str(tmp_path / "data")
    assert "data_dir" not in plan.parameters["leaf"]  # leaf does not declare it


def test_declared_data_dir_must_exist(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb",
                   'profile = ""\nout_dir = ""\ndata_dir = ""\nvalue = 1\n', "pass")
    spec = load_spec(make_pipeline())
    with pytest.raises(PipelineError, match=r"task 'leaf': data_dir .*data does not exist"):
        check(spec, "smoke")


def test_unknown_claim_id_is_an_error(make_pipeline: MakePipeline) -> None:
    task = leaf_task()
    task["claims"] = ["S1", "S9"]
    spec = load_spec(make_pipeline({"leaf": task}))
    with pytest.raises(PipelineError, match=r"task 'leaf' declares claim 'S9', which is not in claims.yaml"):
        check(spec, "smoke")


def test_a_book_notebook_takes_its_values_and_types_from_its_settings(make_pipeline: MakePipeline,
                                                                     tmp_path: Path) -> None:
    """The runner injects the settings dataclass's paper values and checks overrides by their types, even where
    the notebook's cell says otherwise (the dataclass is the home; the cell is written from it)."""
    cell = book_parameters_cell("02_theory").replace("\nL = 20.0\n", "\nL = 3.0\n").replace("\nTs = 0.01\n", "\n")
    write_notebook(tmp_path / "notebooks" / "02_theory.ipynb", cell,
                   "from fnnbook.tasks.theory import TheorySettings")  # one of the book's notebooks
    task = {**leaf_task(), "notebook": "notebooks/02_theory.ipynb",
            "parameters": {"paper": {}, "smoke": {"L": 10}}}
    spec = load_spec(make_pipeline({"theory": task}))
    assert {k: check(spec, "paper").parameters["theory"][k] for k in ("L", "Ts")} == {"L": 20.0, "Ts": 0.01}
    assert check(spec, "smoke").parameters["theory"]["L"] == 10
    bad = {**task, "parameters": {"paper": {}, "smoke": {"Ts": "fast"}}}
    with pytest.raises(PipelineError, match=r"parameter 'Ts': got str 'fast', but the notebook's default "
                                            r"is float 0.01"):
        check(load_spec(make_pipeline({"theory": bad})), "smoke")
