"""Grid point names are one-to-one: no two points share a folder, none is dropped."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fnnbook import load_spec
from fnnbook.spec import _point_name

from .nbfactory import MakePipeline, leaf_task

_VALUES = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=8),
                       lambda inner: st.lists(inner, max_size=3), max_leaves=6)


@settings(max_examples=300, deadline=None)
@given(a=_VALUES, b=_VALUES)
def test_distinct_values_get_distinct_names(a: object, b: object) -> None:
    same = json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)
    assert (_point_name("t", {"x0": a}) == _point_name("t", {"x0": b})) == same


@pytest.mark.parametrize(("a", "b"), [
    ([9.0, 1.0], [9.0, -1.0]),    # the sign was mapped to '_'
    ([[1, 2], 3], [1, [2, 3]]),   # nested lists
    (0.1, 0.1000000000000001),    # floats that print alike in short forms
    (1, 1.0), (1, "1"),
    ("a b", "a_b"), ("a/b", "a-b"), ("a__b", "a_b"),   # strings with separators
])
def test_named_collisions_of_the_old_scheme(a: object, b: object) -> None:
    assert _point_name("t", {"x0": a}) != _point_name("t", {"x0": b})


def test_a_grid_of_signed_vectors_gives_every_point(make_pipeline: MakePipeline) -> None:
    spec = load_spec(make_pipeline({"pt": {**leaf_task(), "grid": {"x0": [[9.0, 1.0], [9.0, -1.0]]}}},
                                   parts=[{"title": "P", "tasks": ["pt"]}]))
    points = spec.grids["pt"]
    assert len(points) == 2
    assert [spec.tasks[p].parameters["smoke"]["x0"] for p in points] == [[9.0, 1.0], [9.0, -1.0]]
    assert all(p.replace("_", "").replace(".", "").isalnum() for p in points)  # a plain folder name
    assert _point_name("pt", {"seed": 3}) == "pt__seed_3"  # plain seeds read as before
