"""``fnn-pipeline data fetch``: download the published throws (Sec. 5.1) and the authors' trained networks,
and check them.

The two files lie, byte-identical, in two public repositories, each pinned at a commit: the authors'
official code release, then the repository the paper's review pointed to. :mod:`pooch` downloads each file
from the first source that serves it, once (no retries), and keeps it only when its SHA-256 is the one
pinned in :data:`fnnlib.data.bottle.BOTTLE_FILES`; a refused file leaves nothing in the data directory.

>>> fetch_bottle("data")      # doctest: +SKIP
[PosixPath('data/bottle/Training_dataset.mat'), PosixPath('data/bottle/Testing_dataset.mat')]

The authors' trained networks (what the why profile evaluates beside ours) come the same way from the
official release, every file pinned in :data:`fnnlib.release.RELEASE_FILES`, into ``<data_dir>/release/``
(:func:`fetch_release`). They are read from there and never redistributed.

The cascaded tanks benchmark's data file (the "Beyond the paper" chapter on a real plant) comes from its
official archive, ``CascadedTanksFiles.zip`` on 4TU.ResearchData (then nonlinearbenchmark.org): pooch
downloads the archive, extracts the one member ``CascadedTanksFiles/dataBenchmark.mat`` and it is kept only
when its SHA-256 is :data:`fnnlib.data.tanks.TANKS_SHA256` (:func:`fetch_tanks`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from fnnlib.data.bottle import BOTTLE_FILES, DataError
from fnnlib.release import RELEASE_FILES
from fnnlib.data.tanks import TANKS_ARCHIVE_MEMBER, TANKS_FILE, TANKS_SHA256, TANKS_SOURCES
from fnnlib.io import file_sha256

__all__ = ["BOTTLE_SOURCES", "RELEASE_SOURCES", "TANKS_SOURCES", "fetch_bottle", "fetch_release", "fetch_tanks"]

_RAW = "https://raw.githubusercontent.com"
#: where the throws are published, tried in this order: label -> URL template with ``{name}`` (a key of
#: BOTTLE_FILES); each at a pinned commit, so the files cannot change under the pinned SHA-256
BOTTLE_SOURCES: dict[str, str] = {
    "official release": f"{_RAW}/JIAjindou/Feedback-neural-network/395154347267c7088fcdcecd89f6df1355758117/"
                        "irregular_object/Dataset_construction/{name}",
    "review repository": f"{_RAW}/anonymity-tempo/Feedback_NN_irregular_object/"
                         "3f314167516c26bea8e1ad86a8f84ada911900bd/Dataset_construction/{name}",
}
#: where the authors' trained networks are published: the official release at the same pinned commit; ``{name}``
#: is a key of RELEASE_FILES (a path in that repository)
RELEASE_SOURCES: dict[str, str] = {
    "official release": f"{_RAW}/JIAjindou/Feedback-neural-network/395154347267c7088fcdcecd89f6df1355758117/{{name}}",
}


def _why(exc: Exception) -> str:
    """A download failure in a few words."""
    import requests  # noqa: PLC0415 (pooch's HTTP client)

    if isinstance(exc, requests.HTTPError) and exc.response is not None:
        return f"HTTP {exc.response.status_code}"
    if isinstance(exc, requests.Timeout):
        return "timed out"
    if isinstance(exc, requests.ConnectionError):
        return "no connection"
    if isinstance(exc, ValueError):  # pooch's hash check
        return "SHA-256 is not the pinned one, file refused"
    return f"{type(exc).__name__}: {exc}"


def _download(url: str, folder: Path, name: str, digest: str, timeout: float) -> None:
    """One attempt at ``url``: pooch writes to a temporary file, checks its SHA-256, then moves it in place."""
    import pooch  # noqa: PLC0415 (only the fetch needs it)

    logger = pooch.get_logger()  # pooch's own logger says "Downloading ..." at INFO: our echo says it once
    level = logger.level
    logger.setLevel("WARNING")
    try:
        pooch.retrieve(url, known_hash=f"sha256:{digest}", fname=Path(name).name, path=folder / Path(name).parent,
                       downloader=pooch.HTTPDownloader(progressbar=False, timeout=timeout))
    finally:
        logger.setLevel(level)


def fetch_bottle(
    data_dir: str | os.PathLike[str],
    *,
    sources: Mapping[str, str] | None = None,
    timeout: float = 60.0,
    echo: Callable[[str], None] = print,
) -> list[Path]:
    """Download each file of :data:`~fnnlib.data.bottle.BOTTLE_FILES` into ``<data_dir>/bottle/``.

    A file already there with the pinned SHA-256 is kept; otherwise each source is tried once, in order,
    until one serves the file with the pinned SHA-256.

    Parameters
    ----------
    data_dir : path-like
        The data directory (``--data-dir``; the pipeline's ``data_dir``).
    sources : mapping of str to str, optional
        Label -> URL template with ``{name}``, tried in order (default: :data:`BOTTLE_SOURCES`).
    timeout : float
        Seconds per request.
    echo : callable
        Receives one line per file.

    Returns
    -------
    list of Path
        The checked files.

    Raises
    ------
    DataError
        If no source serves a file with the pinned SHA-256 (the message names each source's failure).
    """
    files = {name: digest for name, (_, _, digest) in BOTTLE_FILES.items()}
    return _fetch(Path(data_dir) / "bottle", files, BOTTLE_SOURCES if sources is None else sources, timeout, echo)


def fetch_release(data_dir: str | os.PathLike[str], **options: Any) -> list[Path]:
    """Download each file of :data:`~fnnlib.release.RELEASE_FILES` into ``<data_dir>/release/`` (same
    relative paths as in the release), as :func:`fetch_bottle` does for the throws, with its options
    (``sources`` default :data:`RELEASE_SOURCES`, ``timeout``, ``echo``); one line for the files already there.

    Raises
    ------
    DataError
        If no source serves a file with the pinned SHA-256.
    """
    sources = options.pop("sources", None)
    return _fetch(Path(data_dir) / "release", RELEASE_FILES, RELEASE_SOURCES if sources is None else sources,
                  options.pop("timeout", 60.0), options.pop("echo", print), each_present=False, **options)


def _fetch(folder: Path, files: Mapping[str, str], sources: Mapping[str, str], timeout: float,
           echo: Callable[[str], None], *, each_present: bool = True) -> list[Path]:
    """Each of ``files`` (name -> SHA-256) into ``folder``: kept when present and good, else downloaded from the
    first source that serves it with that SHA-256."""
    sources = dict(sources)
    bad = [label for label, url in sources.items() if "{name}" not in url]
    if not sources or bad:
        raise DataError(f"each source must be a URL template containing {{name}}; got {sources!r}")
    existed = {folder, *(p for p in folder.rglob("*") if p.is_dir())} if folder.is_dir() else set()
    try:
        return _fetch_each(folder, files, sources, timeout, echo, each_present)
    except BaseException:
        _remove_new_empty_folders(folder, existed)
        raise


def _remove_new_empty_folders(folder: Path, existed: set[Path]) -> None:
    """Remove the folders below ``folder`` (and itself) that a failed fetch created and left empty: an empty
    ``release/.../trained_model/`` must not look like a release."""
    if not folder.is_dir():
        return
    for path in sorted((p for p in folder.rglob("*") if p.is_dir()), key=lambda p: len(p.parts), reverse=True):
        if path not in existed:
            with contextlib.suppress(OSError):
                path.rmdir()  # only when empty
    if folder not in existed:
        with contextlib.suppress(OSError):
            folder.rmdir()


def _fetch_each(folder: Path, files: Mapping[str, str], sources: Mapping[str, str], timeout: float,
                echo: Callable[[str], None], each_present: bool) -> list[Path]:
    import requests  # noqa: PLC0415 (pooch's HTTP client)

    done, present = [], 0
    for name, digest in files.items():
        path = folder / name
        if path.is_file() and file_sha256(path) == digest:
            if each_present:
                echo(f"{path}: present, SHA-256 ok")
            present += 1
            done.append(path)
            continue
        failures = []
        for label, url in sources.items():
            try:
                _download(url.format(name=name), folder, name, digest, timeout)
            except (requests.RequestException, ValueError, OSError) as exc:  # ValueError: pooch's hash check
                failures.append(f"{label} ({url.format(name=name)}): {_why(exc)}")
                continue
            echo(f"{path}: downloaded from the {label}, SHA-256 ok")
            done.append(path)
            break
        else:
            raise DataError(f"cannot download {name}: " + "; ".join(failures))
    if present and not each_present:
        echo(f"{folder}: {present} of {len(files)} files present, SHA-256 ok")
    return done


def fetch_tanks(data_dir: str | os.PathLike[str], *, sources: Mapping[str, str] | None = None, timeout: float = 60.0,
                echo: Callable[[str], None] = print) -> Path:
    """The cascaded tanks benchmark's ``dataBenchmark.mat`` into ``<data_dir>/cascaded_tanks/``.

    A file already there with the pinned SHA-256 is kept; otherwise each source (a URL of the official
    archive ``CascadedTanksFiles.zip``) is tried once, in order: pooch downloads the archive into a temporary
    folder and extracts the member :data:`~fnnlib.data.tanks.TANKS_ARCHIVE_MEMBER`, which is moved in place
    only when its SHA-256 is :data:`~fnnlib.data.tanks.TANKS_SHA256` (the archive itself is not kept).

    Parameters
    ----------
    data_dir : path-like
        The data directory.
    sources : mapping of str to str, optional
        Label -> URL of the archive, tried in order (default: :data:`~fnnlib.data.tanks.TANKS_SOURCES`).
    timeout : float
        Seconds per request.
    echo : callable
        Receives one line.

    Returns
    -------
    Path
        The checked file.

    Raises
    ------
    DataError
        If no source serves an archive whose member has the pinned SHA-256 (the message names each failure).
    """
    import shutil  # noqa: PLC0415
    import tempfile  # noqa: PLC0415
    import zipfile  # noqa: PLC0415

    import pooch  # noqa: PLC0415 (only the fetch needs it)
    import requests  # noqa: PLC0415 (pooch's HTTP client)

    folder = Path(data_dir) / "cascaded_tanks"
    path = folder / TANKS_FILE
    if path.is_file() and file_sha256(path) == TANKS_SHA256:
        echo(f"{path}: present, SHA-256 ok")
        return path
    sources = dict(TANKS_SOURCES if sources is None else sources)
    if not sources:
        raise DataError("no source for the cascaded tanks archive")
    failures = []
    for label, url in sources.items():
        with tempfile.TemporaryDirectory(prefix="fnn-tanks-") as tmp:
            logger = pooch.get_logger()
            level = logger.level
            logger.setLevel("WARNING")
            try:
                got = pooch.retrieve(url, known_hash=None, fname="CascadedTanksFiles.zip", path=tmp,
                                     downloader=pooch.HTTPDownloader(progressbar=False, timeout=timeout),
                                     processor=pooch.Unzip(members=[TANKS_ARCHIVE_MEMBER]))
            except (requests.RequestException, ValueError, OSError, zipfile.BadZipFile, KeyError) as exc:
                why = f"{TANKS_ARCHIVE_MEMBER} not in the archive" if isinstance(exc, KeyError) else (
                    "not a zip archive" if isinstance(exc, zipfile.BadZipFile) else _why(exc))
                failures.append(f"{label} ({url}): {why}")
                continue
            finally:
                logger.setLevel(level)
            found = [Path(p) for p in got if Path(p).as_posix().endswith(TANKS_ARCHIVE_MEMBER)]
            if not found:  # pooch extracts nothing when the member is absent
                failures.append(f"{label} ({url}): {TANKS_ARCHIVE_MEMBER} not in the archive")
                continue
            member = found[0]
            if file_sha256(member) != TANKS_SHA256:
                failures.append(f"{label} ({url}): {TANKS_ARCHIVE_MEMBER}'s SHA-256 is not the pinned one, file refused")
                continue
            folder.mkdir(parents=True, exist_ok=True)
            shutil.move(str(member), path)
        echo(f"{path}: extracted from the archive on {label}, SHA-256 ok")
        return path
    raise DataError("cannot get the cascaded tanks data: " + "; ".join(failures))
