"""The smoke-profile book as a reader sees it: quiet pages, and every page read in headless Chromium.

The book is built once per run from the shared smoke outputs (``smoke_outputs``
in ``tests/conftest.py``), in the bare copy of the repository they ran in (a
new user's clone: nothing outside it is read), and read by Debian's chromium
through Selenium with the network unused (see :mod:`reader.browser`). Without chromium and
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
from fnnbook.scoreboard import read_claims
from reader.browser import missing_browser, read_book

SMOKE = "smoke"
#: one xdist worker builds the book and reads it; the other runs other tests meanwhile (``--dist loadgroup``)
pytestmark = pytest.mark.xdist_group("book")
#: what solver, kernel or library chatter looks like in an executed cell's output
NOISE = re.compile(r"ERROR in osqp|Problem data validation|\bWarning\b|Traceback \(most recent call last\)")


@pytest.fixture(scope="session")
def smoke_book(smoke_outputs) -> Path:
    """The book of the bare copy, built from this run's smoke outputs (once for all xdist workers), as
    ``fnn-pipeline book`` builds it there; its ``_build/html``."""
    book = smoke_outputs.spec.root / "book"
    html = book / "_build" / "html"
    report = smoke_outputs.run()  # every task (each under its own lock), before taking the book's
    assert report.ok, [(o.task, o.status, o.message) for o in report.outcomes]
    with FileLock(str(smoke_outputs.spec.output_root / "book.lock")):
        if not (html / "index.html").is_file():
            assemble_book(smoke_outputs.spec, SMOKE, book)
            build_book(book, quiet=True)
    return html


@pytest.mark.notebook
def test_a_new_user_gets_the_whole_book_from_the_repository_alone(smoke_book: Path, smoke_outputs) -> None:
    """The copy has nothing beside it; what the run read lies inside it; the scoreboard lists every claim."""
    spec = smoke_outputs.spec
    assert [p.name for p in spec.root.parent.iterdir()] == [spec.root.name]
    for path in (spec.claims_file, spec.output_root, spec.data_dir, smoke_book):
        assert path.resolve().is_relative_to(spec.root.resolve()), f"{path} is outside the copy"
    ids = [c.id for c in read_claims(spec.claims_file)]
    scoreboard = (smoke_book / "_generated" / "scoreboard.html").read_text(encoding="utf-8")
    assert len(ids) == 29  # S1-S11, D1-D4, O1-O2, Q1-Q6 and B1-B6 (B4-B6: the cascaded tanks)
    listed = [cid for cid in ids if f'id="claim-{cid.lower()}"' in scoreboard]
    assert listed == ids, f"not on the scoreboard: {sorted(set(ids) - set(listed))}"
    assert (smoke_book / "_generated" / "api.html").is_file()


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
