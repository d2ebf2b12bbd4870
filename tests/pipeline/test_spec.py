"""Loading and validating pipeline.yaml."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from fnnbook import PipelineError, PipelineSpec, load_spec, read_parameters

from .nbfactory import MakePipeline, child_task, leaf_task


def test_loads_and_resolves_paths(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    spec = load_spec(make_pipeline({"child": child_task(), "leaf": leaf_task()}))
    assert list(spec.tasks) == ["leaf", "child"]  # upstream first, whatever the file order
    assert spec.root == tmp_path
    assert spec.output_root == tmp_path / "outputs"
    assert spec.claims_file == tmp_path / "claims.yaml"
    assert spec.data_dir == tmp_path / "data"
    assert spec.tasks["leaf"].notebook == tmp_path / "notebooks" / "leaf.ipynb"
    assert spec.tasks["leaf"].products == ("results.json", "value.txt")
    assert spec.profiles == ("paper", "smoke")
    assert spec.closure(["child"]) == ["leaf", "child"]
    assert spec.closure(["leaf"]) == ["leaf"]
    moved = spec.with_paths(output_root=tmp_path / "elsewhere")
    assert moved.output_dir("smoke", "leaf") == tmp_path / "elsewhere" / "smoke" / "leaf"


def test_the_repository_pipeline_parses() -> None:
    """The real pipeline.yaml is well formed (notebooks may still be missing while it grows)."""
    root = Path(__file__).resolve().parents[2]
    try:
        spec = load_spec(root / "pipeline.yaml")
    except PipelineError as exc:
        if "does not exist" not in str(exc):
            raise
        pytest.skip(f"a notebook is not written yet: {exc}")
    assert spec.parts


def test_the_repository_profiles_list_only_overrides() -> None:
    """A notebook's parameters cell holds the paper values (the why values for a why task); no profile repeats
    one of them."""
    root = Path(__file__).resolve().parents[2]
    spec = load_spec(root / "pipeline.yaml")
    for task in spec.tasks.values():
        defaults = read_parameters(task.notebook)
        own = "paper" if "paper" in task.parameters and "paper" not in task.inherited else "why"
        assert set(task.parameters[own]) <= _grid_keys(spec), task.name  # only a grid point's own value
        for profile, values in task.parameters.items():
            same = [k for k, v in values.items() if k in defaults and repr(defaults[k]) == repr(v)
                    and not _from_shared_block(spec, k) and k not in _grid_keys(spec)]
            assert not same, f"{task.name}/{profile} repeats notebook defaults: {same}"


def _grid_keys(spec: PipelineSpec) -> set[str]:
    """The parameters some task's ``grid`` sets (a point may take the notebook's default as one value)."""
    tasks = yaml.safe_load(spec.path.read_text())["tasks"]
    return {k for t in tasks.values() for k in (t.get("grid") or {})}


def _from_shared_block(spec: PipelineSpec, name: str) -> bool:
    shared = yaml.safe_load(spec.path.read_text()).get("shared") or {}
    return any(name in block for block in shared.values())


def test_shared_blocks_merge_into_profiles(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    make_pipeline()
    (tmp_path / "pipeline.yaml").write_text("""\
claims_file: claims.yaml
output_root: outputs
shared:
  small: &small {value: 7, scale: 0.5}
parts: [{title: One, tasks: [leaf]}]
tasks:
  leaf:
    title: Leaf
    notebook: notebooks/leaf.ipynb
    products: [value.txt]
    parameters:
      paper: {}
      smoke:
        <<: *small
        scale: 2.0
""")
    spec = load_spec(tmp_path / "pipeline.yaml")
    assert spec.tasks["leaf"].parameters == {"paper": {}, "smoke": {"value": 7, "scale": 2.0}}
    (tmp_path / "pipeline.yaml").write_text("claims_file: C\noutput_root: o\nshared: [1]\nparts: []\ntasks: {}\n")
    with pytest.raises(PipelineError, match="shared must be a mapping"):
        load_spec(tmp_path / "pipeline.yaml")


def test_cycle_is_an_error(make_pipeline: MakePipeline) -> None:
    leaf = leaf_task()
    leaf["upstream"] = ["child"]
    with pytest.raises(PipelineError, match=r"upstream tasks form a cycle: (leaf -> child -> leaf|"
                                            r"child -> leaf -> child)"):
        load_spec(make_pipeline({"leaf": leaf, "child": child_task()}))


def test_self_upstream_is_an_error(make_pipeline: MakePipeline) -> None:
    leaf = leaf_task()
    leaf["upstream"] = ["leaf"]
    with pytest.raises(PipelineError, match=r"task 'leaf' lists itself as upstream"):
        load_spec(make_pipeline({"leaf": leaf}))


def test_unknown_upstream_is_an_error(make_pipeline: MakePipeline) -> None:
    child = child_task()
    child["upstream"] = ["lef"]
    with pytest.raises(PipelineError, match=r"task 'child': upstream task 'lef' does not exist "
                                            r"\(did you mean 'leaf'\?\)"):
        load_spec(make_pipeline({"leaf": leaf_task(), "child": child}))


def test_missing_notebook_is_an_error(make_pipeline: MakePipeline) -> None:
    leaf = leaf_task()
    leaf["notebook"] = "notebooks/nope.ipynb"
    with pytest.raises(PipelineError, match=r"task 'leaf': notebook 'notebooks/nope.ipynb' does not exist"):
        load_spec(make_pipeline({"leaf": leaf}))


def test_unknown_top_level_key_is_an_error(make_pipeline: MakePipeline) -> None:
    with pytest.raises(PipelineError, match=r"pipeline.yaml: unknown key 'output_rot' \(did you mean "
                                            r"'output_root'\?\)"):
        load_spec(make_pipeline(output_rot="x"))


def test_unknown_task_key_is_an_error(make_pipeline: MakePipeline) -> None:
    leaf = leaf_task()
    leaf["product"] = []
    with pytest.raises(PipelineError, match=r"task 'leaf': unknown key 'product' \(did you mean "
                                            r"'products'\?\)"):
        load_spec(make_pipeline({"leaf": leaf}))


def test_missing_task_key_is_an_error(make_pipeline: MakePipeline) -> None:
    leaf = leaf_task()
    del leaf["products"]
    with pytest.raises(PipelineError, match=r"task 'leaf': missing key 'products'"):
        load_spec(make_pipeline({"leaf": leaf}))


def test_task_in_no_part_is_an_error(make_pipeline: MakePipeline) -> None:
    with pytest.raises(PipelineError, match=r"tasks in no part: child"):
        load_spec(make_pipeline({"leaf": leaf_task(), "child": child_task()},
                                parts=[{"title": "One", "tasks": ["leaf"]}]))


def test_part_with_unknown_task_is_an_error(make_pipeline: MakePipeline) -> None:
    with pytest.raises(PipelineError, match=r"parts\[0\] \('One'\) lists task 'leaff', which does not "
                                            r"exist \(did you mean 'leaf'\?\)"):
        load_spec(make_pipeline(parts=[{"title": "One", "tasks": ["leaf", "leaff"]}]))


def test_task_in_two_parts_is_an_error(make_pipeline: MakePipeline) -> None:
    with pytest.raises(PipelineError, match=r"task 'leaf' is listed in two parts: 'One' and 'Two'"):
        load_spec(make_pipeline(parts=[{"title": "One", "tasks": ["leaf"]},
                                       {"title": "Two", "tasks": ["leaf"]}]))


@pytest.mark.parametrize("product", ["/abs/file", "../escape.txt"])
def test_product_outside_output_is_an_error(make_pipeline: MakePipeline, product: str) -> None:
    leaf = leaf_task()
    leaf["products"] = [product]
    with pytest.raises(PipelineError, match=r"must be a relative path inside the task's output folder"):
        load_spec(make_pipeline({"leaf": leaf}))


def test_bad_task_name_is_an_error(make_pipeline: MakePipeline) -> None:
    with pytest.raises(PipelineError, match=r"task '_x': a task name must start with a letter"):
        load_spec(make_pipeline({"_x": leaf_task()}))


def test_unknown_task_selection_is_an_error(make_pipeline: MakePipeline) -> None:
    spec = load_spec(make_pipeline())
    with pytest.raises(PipelineError, match=r"no task named 'lef' \(did you mean 'leaf'\?\)"):
        spec.closure(["lef"])


def test_invalid_yaml_is_an_error(tmp_path: Path) -> None:
    bad = tmp_path / "pipeline.yaml"
    bad.write_text("tasks: [unclosed\n")
    with pytest.raises(PipelineError, match=r"is not valid YAML"):
        load_spec(bad)
    with pytest.raises(PipelineError, match=r"does not exist"):
        load_spec(tmp_path / "missing.yaml")

