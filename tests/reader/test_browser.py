"""The smoke-profile book as a reader sees it: quiet pages, and every page read in headless Chromium.

The book is built once per run from the shared smoke outputs (``smoke_outputs``
in ``tests/conftest.py``) and read by Debian's chromium through Selenium with
the network unused (see :mod:`reader.browser`). Without chromium and
chromium-driver the browser tests are skipped with the command that installs
them. ``BOOK_SCREENSHOTS=DIR`` saves the scoreboard and the spiral page as
whole-page PNGs there.
"""

from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest
from bs4 import BeautifulSoup
from filelock import FileLock

from fnnbook.book import assemble_book, build_book
from reader.browser import missing_browser, read_book

REPO_BOOK = Path(__file__).resolve().parents[2] / "book"
SMOKE = "smoke"
#: what solver, kernel or library chatter looks like in an executed cell's output
NOISE = re.compile(r"ERROR in osqp|Problem data validation|\bWarning\b|Traceback \(most recent call last\)")


@pytest.fixture(scope="session")
def smoke_book(smoke_outputs) -> Path:
    """The book built from this run's smoke outputs (once for all xdist workers); its ``_build/html``."""
    if not smoke_outputs.spec.claims_file.is_file():  # the scoreboard lists the claims of the shared CLAIMS.md
        pytest.skip(f"no claims file at {smoke_outputs.spec.claims_file}: the book cannot be built here")
    book = smoke_outputs.spec.output_root.parent / "smoke-book"
    html = book / "_build" / "html"
    report = smoke_outputs.run()  # every task (each under its own lock), before taking the book's
    assert report.ok, [(o.task, o.status, o.message) for o in report.outcomes]
    with FileLock(str(smoke_outputs.spec.output_root.parent / "smoke-book.lock")):
        if not (html / "index.html").is_file():
            shutil.rmtree(book, ignore_errors=True)
            shutil.copytree(REPO_BOOK, book, ignore=shutil.ignore_patterns("_build", "_generated", "_toc.yml"))
            assemble_book(smoke_outputs.spec, SMOKE, book)
            build_book(book, quiet=True)
    return html


def _browser() -> None:
    why = missing_browser()
    if why:
        pytest.skip(f"the browser test needs Chromium: {why}")


@pytest.mark.notebook
def test_pages_carry_no_noise_and_no_machine_paths(smoke_book: Path, smoke_outputs) -> None:
    root = str(smoke_outputs.spec.output_root)
    absolute = re.compile(r"(?<![.\w])" + re.escape(root))  # the path itself, not ../../ relative to the repo
    pages = sorted((smoke_book / "_generated").glob("*/*.html"))  # the executed notebooks
    assert len(pages) >= 8
    for page in pages:
        text = page.read_text(encoding="utf-8")
        assert not absolute.search(text), f"{page.name} shows the absolute path {root}"
        outputs = "\n".join(o.get_text() for o in BeautifulSoup(text, "html.parser").select(".cell_output"))
        assert outputs, f"{page.name} has no cell outputs"
        noise = NOISE.search(outputs)
        assert noise is None, (f"{page.name} shows solver or kernel noise: "
                               f"{outputs[noise.start():noise.start() + 120]!r}")


@pytest.mark.notebook
def test_every_page_reads_clean_in_chromium(smoke_book: Path) -> None:
    _browser()
    shots = None
    if os.environ.get("BOOK_SCREENSHOTS"):
        folder = Path(os.environ["BOOK_SCREENSHOTS"])
        folder.mkdir(parents=True, exist_ok=True)
        shots = {"_generated/scoreboard.html": folder / "scoreboard.png",
                 "_generated/spiral/spiral.html": folder / "spiral.png"}
    problems = read_book(smoke_book, search_for="S5", screenshots=shots)
    assert problems == []


@pytest.mark.notebook
def test_chromium_check_catches_a_broken_book(smoke_book: Path, tmp_path: Path) -> None:
    _browser()
    html = tmp_path / "html"
    shutil.copytree(smoke_book, html)
    spiral = html / "_generated" / "spiral" / "spiral.html"
    text = spiral.read_text(encoding="utf-8")
    assert "_static/mathjax/tex-chtml.js" in text
    image = re.search(r'<img[^>]+src="\.\./\.\./(_images/[^"]+)"', text).group(1)
    (html / image).unlink()  # a figure that is gone
    spiral.write_text(text.replace("_static/mathjax/tex-chtml.js", "_static/mathjax/missing.js")  # no MathJax
                      .replace("</article>", '<a href="nowhere.html">a dead link</a>'
                               '<img src="http://example.invalid/pixel.png" alt="from the web">'
                               "<script>console.error('boom')</script></article>"), encoding="utf-8")
    (html / "searchindex.js").write_text('Search.setIndex({"docnames": [], "filenames": [], "titles": [], '
                                         '"terms": {}, "titleterms": {}, "objects": {}, "objnames": {}, '
                                         '"objtypes": {}, "envversion": {}, "alltitles": {}, '
                                         '"indexentries": {}})', encoding="utf-8")
    problems = "\n".join(read_book(html, search_for="S5", only=["_generated/spiral/spiral.html"]))
    for expected in ("math elements not rendered", "raw TeX delimiters", f"image did not load: file://{html}/{image}",
                     "broken link file://", "nowhere.html", "network request leaves the book: http://example.invalid/",
                     "console error", "boom", "missing.js", "searching 'S5' finds nothing"):
        assert expected in problems, f"{expected!r} not reported; got:\n{problems}"
