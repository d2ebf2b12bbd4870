"""fnnlib's face and the book's API reference (fnnbook.apiref): the face is the method, about 30 names, each
documented with the paper's equation; everything else has a named home and is not on the face."""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass

import pytest

import fnnlib
from fnnbook import apiref
from fnnbook.apiref import GROUPS, SUBPACKAGES, PublicName, public_names, render_api_page, subpackage_names

#: the most names the face may hold (the method's 32 and the 5 option objects its calls take)
FACE_LIMIT = 37
#: a docstring cites the paper: an equation, a theorem, a section, an algorithm or an appendix
CITES = re.compile(r"\b(?:Eqs?\.|Theorem|Sec\.|Alg\.|App\.)")
#: names that moved off the face to a named home (a few of each home); none may come back as an alias
MOVED = {"Spiral": "fnnlib.systems", "colon_range": "fnnlib.paper", "paired_levels": "fnnlib.paper",
         "theorem1_balls": "fnnlib.stability", "rmse": "fnnlib.metrics", "new_figure": "fnnlib.plotting",
         "seed_everything": "fnnlib.seeding", "load_seed_checkpoints": "fnnlib.training",
         "stack_members": "fnnlib.models", "cascade_sweep": "fnnlib.feedback",
         "load_release_spiral_ode": "fnnlib.release", "tanks_records": "fnnlib.data.tanks",
         "ClaimResult": "fnnbook.results", "headline_number": "fnnbook.results", "write_results": "fnnbook.results",
         "set_num_threads": "fnnlib.threads"}


@pytest.fixture(scope="module")
def names() -> list[PublicName]:
    return public_names()


def face() -> list[str]:
    return list(importlib.import_module("fnnlib._api").__all__)


def test_the_face_is_small_and_each_name_cites_the_paper(names: list[PublicName]) -> None:
    assert 20 <= len(face()) <= FACE_LIMIT and len(set(face())) == len(face())
    assert sorted(n.name for n in names) == sorted(face()) == sorted(set(dir(fnnlib)) & set(face()))
    undocumented = [f"fnnlib.{n.name} ({n.kind}, from {n.source})" for n in names if not CITES.search(n.doc)]
    assert undocumented == [], "names of the face whose docstring cites no equation, theorem or section"


def test_moved_names_live_in_their_homes_and_not_on_the_face() -> None:
    for name, home in MOVED.items():
        assert hasattr(importlib.import_module(home), name), (name, home)
        with pytest.raises(AttributeError):
            getattr(fnnlib, name)
        assert name not in face() and name not in dir(fnnlib)


def test_the_face_exports_no_quadrotor_mpc_release_or_book_name() -> None:
    for module in ("fnnlib.quadrotor.mpc", "fnnlib.quadrotor.control", "fnnlib.release", "fnnlib.quadrotor.presets",
                   "fnnlib.paper.spiral_presets", "fnnbook.results"):
        mod = importlib.import_module(module)
        names = list(getattr(mod, "__all__", []))
        assert names and not set(names) & set(face()), module
        objects = {id(getattr(mod, n)) for n in names if callable(getattr(mod, n))}
        assert not objects & {id(getattr(fnnlib, n)) for n in face()}, module  # no alias under another name


def test_every_public_name_is_on_the_page_once_under_its_group(names: list[PublicName]) -> None:
    page = render_api_page(names)
    entries = re.findall(r"^\.\. (?:autoclass|autofunction):: fnnlib\.(\w+)$|^\.\. py:data:: (\w+)$", page, re.M)
    documented = [a or b for a, b in entries]
    assert sorted(documented) == sorted(face()) and len(documented) == len(set(documented))
    headings = re.findall(r"^## (.+)$", page, re.M)
    assert headings == [*GROUPS, "Beyond the face"]
    feedback = page.index("## The feedback layer and the cascade")
    assert feedback < page.index(".. autofunction:: fnnlib.cascade_predict") < page.index("## The neural feedback")
    beyond = page.split("## Beyond the face")[1]
    assert "### `fnnlib.paper`" in beyond and "| `colon_range` |" in beyond.split("### `fnnlib.paper`")[1]
    assert ".. auto" not in beyond  # the subpackages are summarised, the face documented in full
    for module in SUBPACKAGES:
        assert all(n.name not in face() for n in subpackage_names(module)), module


def test_a_missing_docstring_and_an_ungrouped_name_are_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    @dataclass
    class Bare:
        x: int

    assert apiref._own_doc(Bare) == ""  # the dataclass's generated "Bare(x: int)" is no docstring
    assert apiref._own_doc(lambda: None) == ""
    assert apiref._data_doc("NOISE_AMPLIFICATION_LIMIT", "fnnlib.feedback").startswith(":func:`check_gain` warns")
    assert apiref._data_doc("NO_SUCH_NAME", "fnnlib.feedback") == ""
    less = {k: tuple(n for n in v if n != "choose_gain") for k, v in GROUPS.items()}
    monkeypatch.setattr(apiref, "GROUPS", less)
    with pytest.raises(ValueError, match="fnnlib.choose_gain: on the face but in no group"):
        public_names()
    more = {**GROUPS, "Extra": ("Spiral",)}
    monkeypatch.setattr(apiref, "GROUPS", more)
    with pytest.raises(ValueError, match="names 'Spiral', which is not on fnnlib's face"):
        public_names()
