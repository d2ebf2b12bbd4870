"""The suite's xdist groups hold: the book's tests carry the ``@book`` suffix that loadgroup schedules by."""

from __future__ import annotations

import pytest


def test_the_book_tests_form_one_xdist_group(request: pytest.FixtureRequest) -> None:
    """Without the suffix the book's four tests went to both workers, one waiting for the other's build."""
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not a worker of an xdist run with --dist loadgroup")
    book = [item.nodeid for item in request.session.items if "tests/reader/test_browser.py" in item.nodeid]
    if not book:
        pytest.skip("the book's tests are not in this run")
    assert all(nodeid.endswith("@book") for nodeid in book), book
