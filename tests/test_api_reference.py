"""The book's API reference (fnnbook.apiref): every public name of fnnlib documented, and on the page."""

from __future__ import annotations

import re
from dataclasses import dataclass

import pytest

import fnnlib
from fnnbook import apiref
from fnnbook.apiref import GROUPS, PublicName, public_names, render_api_page


@pytest.fixture(scope="module")
def names() -> list[PublicName]:
    return public_names()


def test_every_public_name_has_a_docstring(names: list[PublicName]) -> None:
    assert len(names) == len(set(dir(fnnlib)) & {n.name for n in names}) > 50
    undocumented = [f"fnnlib.{n.name} ({n.kind}, from {n.source})" for n in names if not n.doc.strip()]
    assert undocumented == [], "public names without a docstring (a constant: a #: comment over it)"


def test_every_public_name_is_on_the_page_once_under_its_group(names: list[PublicName]) -> None:
    page = render_api_page(names)
    entries = re.findall(r"^\.\. (?:autoclass|autofunction):: fnnlib\.(\w+)$|^\.\. py:data:: (\w+)$", page, re.M)
    documented = [a or b for a, b in entries]
    assert sorted(documented) == sorted(n.name for n in names) and len(documented) == len(set(documented))
    headings = re.findall(r"^## (.+)$", page, re.M)
    assert headings == [g for g in dict.fromkeys(GROUPS.values()) if any(GROUPS[n.source] == g for n in names)]
    feedback = page.index("## The feedback core")
    assert feedback < page.index(".. autofunction:: fnnlib.cascade_predict") < page.index("## Observers")
    assert ".. autoclass:: fnnlib.Spiral" in page.split("## Systems")[1].split("## Models")[0]


def test_a_missing_docstring_and_an_unknown_module_are_caught(monkeypatch: pytest.MonkeyPatch) -> None:
    @dataclass
    class Bare:
        x: int

    assert apiref._own_doc(Bare) == ""  # the dataclass's generated "Bare(x: int)" is no docstring
    assert apiref._own_doc(lambda: None) == ""
    assert apiref._data_doc("NOISE_AMPLIFICATION_LIMIT", "fnnlib.feedback").startswith(":func:`check_gain` warns")
    assert apiref._data_doc("NO_SUCH_NAME", "fnnlib.feedback") == ""
    monkeypatch.setattr(apiref, "GROUPS", {k: v for k, v in GROUPS.items() if k != "fnnlib.stats"})
    with pytest.raises(ValueError, match="fnnlib.paired_win: imported from 'fnnlib.stats', which has no group"):
        public_names()
