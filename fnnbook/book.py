"""Assemble the jupyter-book from the pipeline's outputs, and build it.

:func:`assemble_book` writes only generated, git-ignored files:
``<book>/_generated/`` (executed notebooks, figures, the scoreboard page, the
API reference) and ``<book>/_toc.yml``.  The hand-written pages (``intro.md``,
``paper_vs_release.md``) and ``_config.yml`` stay as they are.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import yaml

from fnnbook.apiref import API_PAGE, write_api_page
from fnnbook.fingerprint import stored
from fnnbook.layout import holding, read_status
from fnnbook.scoreboard import Missing, plot_verdicts, read_claims, render_scoreboard, score_rows, with_scoreboard_claims
from fnnbook.spec import PipelineError, PipelineSpec
from fnnlib.io import atomic_write, file_sha256
from fnnbook.why import WHYS_FILENAME, Why, read_whys
from fnnbook.results import RESULTS_FILENAME, Results, read_results

__all__ = ["GENERATED", "SHOWN_FILE", "assemble_book", "book_lock", "build_book", "make_book"]

GENERATED = "_generated"
_STATIC_PAGES = ("intro.md", "paper_vs_release.md", "_config.yml")
#: the lock file a build holds on its book folder (one build per folder at a time)
LOCK_FILE = ".book.lock"
#: what a book shows, written beside its pages: ``{"profile": ..., "output_root": ...}``
SHOWN_FILE = "shown.json"
#: what a build writes into the book folder; everything else there is hand-written and copied to the scratch folder
_BUILT = ("_build", GENERATED, "_toc.yml", LOCK_FILE)


@contextlib.contextmanager
def book_lock(book_dir: Path, echo: Callable[[str], None] = print) -> Iterator[None]:
    """Hold the book folder's lock (``fcntl``, released if the process dies); a second build waits, and says so."""
    import fcntl  # noqa: PLC0415 (POSIX)

    book_dir.mkdir(parents=True, exist_ok=True)
    with open(book_dir / LOCK_FILE, "a+b") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            echo(f"waiting for another book build on {book_dir} to finish")
            fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def make_book(spec: PipelineSpec, profile: str, book_dir: str | os.PathLike[str], *, api: bool = True,
              quiet: bool = False, echo: Callable[[str], None] = print) -> Path:
    """Assemble and build the book of ``profile`` into ``book_dir``, safe beside another build of the same folder.

    The build holds the folder's lock (:func:`book_lock`: a second build waits for the first), assembles and
    builds in a scratch folder of its own beside the book (its hand-written pages copied in), then swaps the
    generated pages, the table of contents and the HTML in by renames: a reader sees the last complete book,
    and each book's pages are its own output root's. The book records what it shows (:data:`SHOWN_FILE`, and
    a line of the scoreboard).

    Returns
    -------
    Path
        ``<book_dir>/_build/html``.
    """
    book = Path(book_dir).resolve()
    with book_lock(book, echo):
        scratch = Path(tempfile.mkdtemp(prefix=".build-", dir=book))
        try:
            work = scratch / "book"
            shutil.copytree(book, work, ignore=lambda folder, names: [
                n for n in names if Path(folder) == book and (n in _BUILT or n.startswith((".build-", f"{GENERATED}.")))])
            assemble_book(spec, profile, work, api=api)
            build_book(work, quiet=quiet)
            for name in (GENERATED, "_build"):
                _swap_in(work / name, book / name)
            os.replace(work / "_toc.yml", book / "_toc.yml")
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
    return book / "_build" / "html"


#: a code cell longer than this (in lines) starts folded, like every cell that draws a figure
FOLD_LINES = 10
#: a text output longer than this (in lines: per-seed numbers, tables) shows in a box that scrolls
SCROLL_LINES = 20
_FOLD_TAGS = ("hide-input", "remove-input", "remove-cell", "hide-cell", "show-input")


def _output_lines(cell: Any) -> int:
    """The longest text output of a cell, in lines."""
    longest = 0
    for o in cell.get("outputs", []):
        text = o.get("text") or o.get("data", {}).get("text/plain") or ""
        longest = max(longest, len(("".join(text) if isinstance(text, list) else text).splitlines()))
    return longest


def _fold(cell: Any) -> None:
    """Tag a long or plotting code cell ``hide-input``, unless its source's tags already decide; give a long
    text output a scrolling box (``scroll-output``).

    The reader sees prose, figures and results; the code stays one click
    away, and a dump of per-seed numbers does not push the page's figures
    screens down.  The cell with the injected parameters always stays open.
    """
    tags = list(cell.metadata.get("tags", []))
    if cell.cell_type == "code" and "scroll-output" not in tags and _output_lines(cell) > SCROLL_LINES:
        tags.append("scroll-output")
        cell.metadata["tags"] = tags
    if cell.cell_type != "code" or "injected-parameters" in tags or any(t in tags for t in _FOLD_TAGS):
        return
    draws = any("image/png" in o.get("data", {}) or "image/svg+xml" in o.get("data", {})
                for o in cell.get("outputs", []))
    if draws or len(cell.source.splitlines()) > FOLD_LINES:
        cell.metadata["tags"] = [*tags, "hide-input"]


def _relative_paths(text: str, paths: list[str], root: Path) -> str:
    """Write each absolute path in ``paths`` relative to ``root`` (the repository) inside a notebook's JSON."""
    for path in sorted({p for p in paths if os.path.isabs(p)}, key=len, reverse=True):
        rel = os.path.relpath(path, root)
        for old, new in ((path, rel), (json.dumps(path)[1:-1], json.dumps(rel)[1:-1])):
            text = text.replace(old, new)
    return text


def _shown_path(path: str, root: Path, output_root: Path) -> str:
    """A path as a page shows it: relative to the repository inside it, ``<output root>/...`` inside the
    output root, else unchanged (a relative path is read from the repository, where the runner starts)."""
    p = Path(path) if os.path.isabs(path) else root / path
    p = Path(os.path.normpath(p))
    for base, prefix in ((Path(os.path.normpath(root)), ""), (Path(os.path.normpath(output_root)), "<output root>")):
        if p == base or base in p.parents:
            rel = os.path.relpath(p, base)
            return f"{prefix}/{rel}" if prefix else rel
    return path


def _copy_for_book(src: Path, dst: Path, root: Path, *, out_dir: Path | None = None,
                   output_root: Path | None = None) -> None:
    """Copy an executed notebook for the book: defaults hidden, code folded, no path of the machine shown.

    * The cell of default parameters is removed: papermill's injected cell
      right after it shows the values the run used, so the defaults would
      only mislead a reader.
    * Long and plotting code cells are folded (:func:`_fold`).
    * The paths papermill injected, wherever they appear (sources, outputs): ``data_dir`` reads ``DATA_DIR``
      (the data directory given to the run), ``out_dir`` the task's output folder (``out_dir``, not the
      staging folder it ran in), and the other paths (``upstream_dirs``) relative to the repository ``root``
      or as ``<output root>/...``; the repository root itself is written relative.
    """
    import nbformat

    nb = nbformat.read(src, as_version=4)
    for cell in nb.cells:
        tags = cell.metadata.get("tags", [])
        if "parameters" in tags and "remove-cell" not in tags:
            cell.metadata["tags"] = [*tags, "remove-cell"]
        _fold(cell)
    params = nb.metadata.get("papermill", {}).get("parameters", {})
    output_root = output_root if output_root is not None else root / "outputs"
    shown: dict[str, str] = {}
    for key, value in params.items():
        values = value.values() if isinstance(value, dict) else [value]
        for v in (v for v in values if isinstance(v, str) and "/" in v):  # a path, never a bare word
            if key == "data_dir":
                shown[v] = "DATA_DIR"
            elif key == "out_dir" and out_dir is not None:
                shown[v] = _shown_path(str(out_dir), root, output_root)
            elif key.endswith("_dir") or key.endswith("_dirs"):
                shown[v] = _shown_path(v, root, output_root)
    text = nbformat.writes(nb)
    for old in sorted(shown, key=len, reverse=True):
        for a, b in ((old, shown[old]), (json.dumps(old)[1:-1], json.dumps(shown[old])[1:-1])):
            text = text.replace(a, b)
    dst.write_text(_relative_paths(text, [str(root)], root), encoding="utf-8")


def _not_run_page(title: str, why: str, rerun: str) -> str:
    return (f"# {title}\n\n:::{{warning}}\nNot run: {why}\n:::\n\n"
            "Its claims are listed as *not run* on the scoreboard. Once the cause is fixed, "
            f"`{rerun}` runs this task and `fnn-pipeline book` shows its results here.\n")


def _damage(spec: PipelineSpec, profile: str, name: str, status: dict[str, Any]) -> str:
    """Why a task's outputs cannot be shown ("" when they can): missing, truncated or changed since its run."""
    out = spec.output_dir(profile, name)
    if not out.is_dir():
        said = status.get(name, {})
        return said.get("message") or "its outputs are missing (it has not run in this output root)"
    products = stored(spec, profile, name).get("products")  # outputs made by hand carry no run record
    for product, digest in sorted(products.items() if isinstance(products, dict) else ()):
        if not (out / product).is_file():
            return f"its output {product} is missing"
        if file_sha256(out / product) != digest:
            return f"its output {product} is truncated or changed since its run"
    if not (out / f"{name}.ipynb").is_file():
        return f"its executed notebook {name}.ipynb is missing"
    if (out / RESULTS_FILENAME).is_file():
        try:
            read_results(out / RESULTS_FILENAME)
        except (OSError, ValueError) as exc:
            return f"its {RESULTS_FILENAME} cannot be read ({exc})"
    return ""


def _swap_in(new: Path, final: Path) -> None:
    """Replace ``final`` by ``new`` with renames (the good book stays until the new one is complete)."""
    old = final.with_name(f"{final.name}.old")
    shutil.rmtree(old, ignore_errors=True)
    if final.exists():
        os.rename(final, old)
    os.rename(new, final)
    shutil.rmtree(old, ignore_errors=True)


def assemble_book(spec: PipelineSpec, profile: str, book_dir: str | os.PathLike[str], *, api: bool = True) -> Path:
    """Copy a profile's executed notebooks and figures into the book, write TOC and scoreboard.

    Parameters
    ----------
    spec : PipelineSpec
    profile : str
        Whose outputs (``<output_root>/<profile>/<task>/``) to show.
    book_dir : path-like
        The book folder, holding ``_config.yml``, ``intro.md`` and
        ``paper_vs_release.md``.
    api : bool
        Add the API reference of fnnlib (:mod:`fnnbook.apiref`; its autodoc costs seconds to build).

    Returns
    -------
    Path
        The written ``_toc.yml``.

    Raises
    ------
    PipelineError
        If a hand-written page or the claims file is missing. A task whose
        outputs are missing, truncated or unreadable gets a page saying so
        (and how to rerun it); its claims read "not run: <reason>". The new
        ``_generated/`` is built aside and swapped in only when complete, under
        a reader's share of the outputs' locks (no run writes them meanwhile).
    """
    spec = spec.for_profile(profile)  # the grid points the profile runs
    book = Path(book_dir).resolve()
    for page in _STATIC_PAGES:
        if not (book / page).is_file():
            raise PipelineError(f"book page {book / page} is missing")
    if not spec.claims_file.is_file():
        raise PipelineError(f"claims file {spec.claims_file} does not exist")
    claims = read_claims(spec.claims_file)
    writable = os.access(spec.output_root, os.W_OK)  # a read-only root has no writer to keep out
    with contextlib.ExitStack() as held:
        held.enter_context(book_lock(book))
        for p in (profile, *spec.extended_by(profile)) if writable else ():  # a reader's share of all it shows
            held.enter_context(holding(spec, p, (), read=spec.declares(p) if p != profile else spec.tasks))
        aside = Path(tempfile.mkdtemp(prefix=f"{GENERATED}.new-", dir=book))  # this build's own
        try:
            return _assemble(spec, profile, book, aside, claims, api=api)
        finally:
            shutil.rmtree(aside, ignore_errors=True)  # gone once swapped in, or failed


def _assemble(spec: PipelineSpec, profile: str, book: Path, aside: Path, claims: list[Any], *, api: bool) -> Path:
    generated = book / GENERATED

    stale, unchecked = stale_tasks(spec, profile)
    results: dict[str, Results] = {}
    pages: dict[str, str] = {}
    figures: dict[str, str] = {}
    parts: list[dict[str, Any]] = []
    notes: dict[str, str] = {}
    status = read_status(spec, profile)
    whys: dict[str, Why | Missing] = {}
    why_pages: dict[str, str] = {}
    for part in spec.parts:
        chapters = []
        for name in part.tasks:
            if name in spec.grids:  # grid points are read by their aggregate step, not shown one by one
                continue
            shown_in = _shown_in(spec, profile, name)
            if shown_in is None:  # a task of an extending profile (the whys) that has not run: its claims say so
                whys.update((c, ("not run", _RUN_HINT.get(p, f"fnn-pipeline run --profile {p}")))
                            for p in spec.extended_by(profile) if p in spec.tasks[name].parameters
                            for c in spec.tasks[name].explains)
                continue
            out = spec.output_dir(shown_in, name)
            target = aside / name
            target.mkdir()
            chapters.append({"file": f"{GENERATED}/{name}/{name}"})
            why = _damage(spec, shown_in, name, status if shown_in == profile else read_status(spec, shown_in))
            if why:  # a page that says what is missing and how to rerun, never a hole in the book
                rerun = f"fnn-pipeline run --profile {shown_in} {name}"
                (target / f"{name}.md").write_text(_not_run_page(spec.tasks[name].title, why, rerun),
                                                   encoding="utf-8")
                pages[name] = f"{name}/{name}.md"
                notes[name] = f"not run: {why}"
                continue
            _copy_for_book(out / f"{name}.ipynb", target / f"{name}.ipynb", spec.root, out_dir=out,
                           output_root=spec.output_root)
            if (out / "figures").is_dir():
                shutil.copytree(out / "figures", target / "figures")
            if (out / RESULTS_FILENAME).is_file():
                results[name] = read_results(out / RESULTS_FILENAME)
                shutil.copy2(out / RESULTS_FILENAME, target / RESULTS_FILENAME)
            pages[name] = f"{name}/{name}.ipynb"
            figures[name] = name
            if spec.tasks[name].explains:
                _read_whys(out, name, spec.tasks[name].explains, target, whys, why_pages)
        if chapters:
            parts.append({"caption": part.title, "numbered": True, "chapters": chapters})

    declared = {n: t.claims for n, t in spec.tasks.items()}
    results = with_scoreboard_claims(claims, results, profile, declared)  # B2 from the headlines, then B3
    rows = score_rows(claims, results, declared)
    for row in rows:  # a claim that does not reproduce and has no why says so
        if row.verdict in ("partly", "not reproduced") and row.claim.id not in whys:
            whys[row.claim.id] = ("no why task explains this claim yet", None)
    plot_verdicts(rows, aside / "verdicts.png")
    root = _shown_root(spec)
    stale_claims = {c: stale[n] for n, t in spec.tasks.items() if n in stale for c in t.claims}
    stale_whys = {c: stale[n] for n, t in spec.tasks.items() if n in stale for c in t.explains}
    (aside / "scoreboard.md").write_text(
        render_scoreboard(rows, profile=profile, pages=pages, figures=figures, notes=notes,
                          summary_figure="verdicts.png", whys=whys, why_pages=why_pages, stale=stale_claims,
                          stale_whys=stale_whys, unchecked=unchecked)
        + f"\n*This book shows the outputs of profile `{profile}` in the output root `{root}`.*\n",
        encoding="utf-8")
    (aside / SHOWN_FILE).write_text(json.dumps({"profile": profile, "output_root": root}) + "\n", encoding="utf-8")
    parts.append({"caption": "Results", "chapters": [{"file": f"{GENERATED}/scoreboard"},
                                                     {"file": "paper_vs_release"}]})
    if api:
        write_api_page(aside)
        parts.append({"caption": "Reference", "chapters": [{"file": f"{GENERATED}/{API_PAGE}"}]})
    toc = {"format": "jb-book", "root": "intro", "parts": parts}
    _swap_in(aside, generated)
    path = book / "_toc.yml"
    with atomic_write(path, "w") as fh:
        fh.write("# Generated by fnnbook.book.assemble_book; do not edit.\n" + yaml.safe_dump(toc, sort_keys=False))
    return path


def stale_tasks(spec: PipelineSpec, profile: str) -> tuple[dict[str, str], str]:
    """The tasks of the book of ``profile`` (and of the profiles extending it) whose outputs are there but stale
    (:func:`fnnbook.runner.decide` would rerun them: an input changed since they ran), each with the command that
    refreshes it; and, when that cannot be decided (the pipeline does not check), the reason ("" otherwise)."""
    from fnnbook.runner import check, decide  # noqa: PLC0415 (the runner imports the book's neighbours)
    from fnnbook.outcome import Action  # noqa: PLC0415

    stale: dict[str, str] = {}
    for p in (profile, *spec.extended_by(profile)):
        try:
            plan = check(spec, p, spec.declares(p))
        except PipelineError as exc:
            return stale, str(exc)
        for name, decision in decide(spec, plan).items():
            if decision.action is Action.RUN and name not in stale and stored(spec, p, name):
                home = spec.home(p, name)
                stale[name] = _RUN_HINT.get(home, f"fnn-pipeline run --profile {home} {name}")
    return stale, ""


def _shown_root(spec: PipelineSpec) -> str:
    """The output root, relative to the repository when inside it (no absolute path of this machine in a book)."""
    try:
        return spec.output_root.relative_to(spec.root).as_posix()
    except ValueError:
        return str(spec.output_root)


#: how a reader runs the tasks of a profile that extends the book's (the Makefile's target)
_RUN_HINT = {"why": "make why"}


def _shown_in(spec: PipelineSpec, profile: str, name: str) -> str | None:
    """The profile whose outputs of ``name`` the book of ``profile`` shows: ``profile`` when the task declares
    it; else the first profile extending ``profile`` that the task declares and has outputs in (None: none)."""
    task = spec.tasks[name]
    if profile in task.parameters and profile not in task.inherited:
        return profile
    for p in spec.extended_by(profile):
        if p in task.parameters and p not in task.inherited and spec.output_dir(p, name).is_dir():
            return p
    return None


def _read_whys(out: Path, name: str, explains: Sequence[str], target: Path, whys: dict[str, Why | Missing],
               why_pages: dict[str, str]) -> None:
    """Collect the whys a task wrote (``whys.json``) for the claims it explains; a claim it left out, or a
    file that cannot be read, says so on the row."""
    path = out / WHYS_FILENAME
    try:
        found = read_whys(path) if path.is_file() else {}
        reason = f"not written by {name}"
    except ValueError as exc:
        found, reason = {}, f"{name}'s {WHYS_FILENAME} cannot be read ({exc})"
    for claim in explains:
        if claim in found:
            whys[claim] = found[claim]
            why_pages[claim] = f"{name}/{name}.ipynb"
        else:
            whys[claim] = (reason, None)
    if path.is_file():
        shutil.copy2(path, target / WHYS_FILENAME)


def build_book(book_dir: str | os.PathLike[str], *, quiet: bool = False) -> Path:
    """Build the book's HTML with warnings as errors.

    Runs ``jupyter-book build <book_dir> --warningiserror --keep-going
    --all`` with the running interpreter's ``jupyter-book``; notebooks are
    not executed (``_config.yml`` sets ``execute_notebooks: "off"``).

    Parameters
    ----------
    book_dir : path-like
        An assembled book (see :func:`assemble_book`).
    quiet : bool
        Pass ``--quiet`` (warnings are still shown).

    Returns
    -------
    Path
        ``<book_dir>/_build/html``.

    Raises
    ------
    PipelineError
        If ``jupyter-book`` is missing or the build fails (a warning included).
    """
    book = Path(book_dir).resolve()
    if not (book / "_toc.yml").is_file():
        raise PipelineError(f"{book} has no _toc.yml; run assemble_book first")
    with book_lock(book):
        return _build(book, quiet)


def _build(book: Path, quiet: bool) -> Path:
    exe = Path(sys.executable).parent / "jupyter-book"
    if not exe.is_file():
        found = shutil.which("jupyter-book")
        if found is None:
            raise PipelineError("jupyter-book is not installed (pip install -e '.[book]')")
        exe = Path(found)
    cmd = [str(exe), "build", str(book), "--warningiserror", "--keep-going", "--all"]
    if quiet:
        cmd.append("--quiet")
    done = subprocess.run(cmd, check=False)
    if done.returncode != 0:
        raise PipelineError(f"book build failed (exit {done.returncode}); see the warnings above")
    return book / "_build" / "html"
