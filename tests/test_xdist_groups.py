"""The suite's xdist groups hold: the book's tests carry the ``@book`` suffix that loadgroup schedules by, and the
tests that compile the numba kernels the ``@numba`` one."""

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


def test_the_numba_tests_form_one_xdist_group(request: pytest.FixtureRequest) -> None:
    """Without the group both workers compiled the MPC's kernels at the same moment, ~10 s of CPU each."""
    if not getattr(request.config.option, "loadgroup", False):
        pytest.skip("not a worker of an xdist run with --dist loadgroup")
    compiled = [item.nodeid for item in request.session.items
                if any(f"tests/quadrotor/mpc/{name}" in item.nodeid for name in ("test_compiled.py", "test_backends.py"))]
    if not compiled:
        pytest.skip("the numba tests are not in this run")
    assert all(nodeid.endswith("@numba") for nodeid in compiled), compiled
