"""Open a built book in headless Chromium (Debian's chromium + chromium-driver, driven by Selenium).

:func:`read_book` visits every page of a built book as a reader would, with
the network cut off, and returns the problems it finds (an empty list for a
good book):

* math not rendered: a ``.math`` element without MathJax output, or raw
  ``\\(`` / ``\\[`` / ``$$`` left in the text outside code;
* an image that did not load (``naturalWidth == 0``);
* an internal link to a missing file or a missing ``#anchor``;
* a console message of level SEVERE (a script error, a failed load);
* a request to anything but ``file:``, ``data:``, ``blob:`` or ``about:``;
* the search page not finding ``search_for``.
"""

from __future__ import annotations

import json
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import unquote, urlsplit

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
INSTALL = "apt-get update && apt-get install -y chromium chromium-driver  (as root; .ci/run does this on CI)"
LOCAL_SCHEMES = ("file", "data", "blob", "about", "chrome", "chrome-untrusted", "devtools")  # chrome*: the browser's own pages
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-default-apps", "--disable-dev-shm-usage", "--window-size=1400,1000",
         # no host name resolves: a request to the web fails at once (and is still reported below)
         "--host-resolver-rules=MAP * ~NOTFOUND")


def missing_browser() -> str | None:
    """Why the browser test cannot run here (None when it can)."""
    absent = [str(p) for p in (CHROMIUM, CHROMEDRIVER) if not p.is_file()]
    if absent:
        return f"no {' and no '.join(absent)}; install them with: {INSTALL}"
    try:
        import selenium  # noqa: F401, PLC0415
    except ImportError:
        return "selenium is not installed (pip install -e '.[test]')"
    return None


@contextmanager
def chromium() -> Iterator[object]:
    """A headless Chromium WebDriver with a fresh, empty profile, logging console and network."""
    from selenium import webdriver  # noqa: PLC0415
    from selenium.webdriver.chrome.service import Service  # noqa: PLC0415

    profile = tempfile.mkdtemp(prefix="chromium-profile-")
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in (*FLAGS, f"--user-data-dir={profile}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(executable_path=str(CHROMEDRIVER)))
    try:
        driver.set_page_load_timeout(60)
        driver.set_script_timeout(60)
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


_WAIT_FOR_MATHJAX = """
const done = arguments[arguments.length - 1];
const ready = () => (window.MathJax && MathJax.startup && MathJax.startup.promise)
  ? MathJax.startup.promise.then(() => done("typeset"), (e) => done("error: " + e)) : done("none");
if (document.readyState === "complete") { setTimeout(ready, 50); } else { window.addEventListener("load", () => setTimeout(ready, 50)); }
"""

_PAGE_FACTS = """
const body = document.body.cloneNode(true);
body.querySelectorAll("pre, code, script, style, mjx-container").forEach((e) => e.remove());
const math = Array.from(document.querySelectorAll(".math"));
return {
  raw_math: ["\\\\(", "\\\\[", "$$"].filter((m) => body.innerText.includes(m)),
  math: math.length,
  math_unrendered: math.filter((e) => !e.querySelector("mjx-container")).length,
  images: Array.from(document.images).map((i) => ({src: i.currentSrc || i.src, ok: i.complete && i.naturalWidth > 0})),
  links: Array.from(document.querySelectorAll("a[href]")).map((a) => a.href),
  ids: Array.from(document.querySelectorAll("[id]")).map((e) => e.id),
};
"""

_SEARCH = """
const done = arguments[arguments.length - 1];
const t0 = Date.now();
(function poll() {
  const hits = Array.from(document.querySelectorAll("#search-results li a")).map((a) => a.textContent);
  const status = document.querySelector("#search-results p.search-summary, #search-results > p");
  if (hits.length || (status && /found|did not match/i.test(status.textContent)) || Date.now() - t0 > 20000) {
    done(hits);
  } else { setTimeout(poll, 200); }
})();
"""


def _page_path(url: str) -> Path:
    return Path(unquote(urlsplit(url).path))


def read_book(html: Path, *, search_for: str, screenshots: dict[str, Path] | None = None,
              only: list[str] | None = None) -> list[str]:
    """Visit every page of the built book ``html`` and return the problems found.

    Parameters
    ----------
    html : Path
        The book's ``_build/html`` folder.
    search_for : str
        A word the search page must find (a claim ID).
    screenshots : dict of str to Path, optional
        Page (relative to ``html``) -> PNG to write, the whole page tall.
    only : list of str, optional
        Visit only these pages (relative to ``html``); links into other pages
        are checked for the file alone.
    """
    html = html.resolve()
    pages = sorted(p for p in html.rglob("*.html") if "_static" not in p.parts and "_sources" not in p.parts)
    if only is not None:
        pages = [html / name for name in only]
    problems: list[str] = []
    ids: dict[Path, set[str]] = {}
    links: list[tuple[Path, str]] = []
    with chromium() as driver:
        for page in pages:
            name = page.relative_to(html).as_posix()
            driver.get(page.as_uri())
            state = driver.execute_async_script(_WAIT_FOR_MATHJAX)
            facts = driver.execute_script(_PAGE_FACTS)
            if facts["math"] and state != "typeset":
                problems.append(f"{name}: MathJax did not typeset ({state})")
            if facts["math_unrendered"]:
                problems.append(f"{name}: {facts['math_unrendered']} of {facts['math']} math elements not rendered")
            if facts["raw_math"]:
                problems.append(f"{name}: raw TeX delimiters {facts['raw_math']} in the text")
            problems += [f"{name}: image did not load: {img['src']}" for img in facts["images"] if not img["ok"]]
            ids[page] = set(facts["ids"])
            links += [(page, href) for href in facts["links"]]
            if screenshots and name in screenshots:
                height = driver.execute_script("return document.documentElement.scrollHeight")
                driver.set_window_size(1400, min(int(height) + 100, 12000))
                driver.save_screenshot(str(screenshots[name]))
                driver.set_window_size(1400, 1000)
        driver.get((html / "search.html").as_uri() + f"?q={search_for}")
        hits = driver.execute_async_script(_SEARCH)
        if not hits:
            problems.append(f"search.html: searching {search_for!r} finds nothing")
        for entry in driver.get_log("browser"):
            if entry.get("level") == "SEVERE":
                problems.append(f"console error: {entry.get('message')}")
        for entry in driver.get_log("performance"):
            message = json.loads(entry["message"])["message"]
            if message.get("method") == "Network.requestWillBeSent":
                url = message["params"]["request"]["url"]
                if urlsplit(url).scheme not in LOCAL_SCHEMES:
                    problems.append(f"network request leaves the book: {url}")
    for page, href in links:
        parts = urlsplit(href)
        if parts.scheme != "file":
            continue  # external links are the reader's choice to follow, not requests the page makes
        target = _page_path(href)
        if not target.exists():
            problems.append(f"{page.relative_to(html).as_posix()}: broken link {href}")
        elif parts.fragment and target.suffix == ".html":
            known = ids.get(target)
            if known is not None and unquote(parts.fragment) not in known:
                problems.append(f"{page.relative_to(html).as_posix()}: missing anchor {href}")
    return problems
