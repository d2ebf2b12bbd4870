"""``fnn-pipeline data fetch``: download the authors' published throws (Sec. 5.1) and check them.

The files come from a pinned commit of the paper authors' code release and
must match the SHA-256 sums pinned in :data:`fnnlib.data.bottle.BOTTLE_FILES`;
a file that does not is refused and nothing is left in the data directory.

>>> fetch_bottle("data")      # doctest: +SKIP
[PosixPath('data/bottle/Training_dataset.mat'), PosixPath('data/bottle/Testing_dataset.mat')]
"""

from __future__ import annotations

import hashlib
import os
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path

from fnnlib.data.bottle import BOTTLE_FILES, DataError
from fnnlib.io import atomic_write, file_sha256

__all__ = ["BOTTLE_RELEASE", "BOTTLE_URL", "fetch_bottle"]

#: the authors' release holding the throws: ``owner/repository/commit`` on GitHub (one place to correct)
BOTTLE_RELEASE = "anonymity-tempo/Feedback_NN_irregular_object/3f314167516c26bea8e1ad86a8f84ada911900bd"
#: where the files lie in that release; ``{name}`` is a key of BOTTLE_FILES
BOTTLE_URL = f"https://raw.githubusercontent.com/{BOTTLE_RELEASE}/Dataset_construction/{{name}}"


def fetch_bottle(
    data_dir: str | os.PathLike[str],
    *,
    url: str = BOTTLE_URL,
    timeout: float = 60.0,
    echo: Callable[[str], None] = print,
) -> list[Path]:
    """Download each file of :data:`~fnnlib.data.bottle.BOTTLE_FILES` into ``<data_dir>/bottle/``.

    A file already there with the pinned SHA-256 is kept; any other is
    replaced only by a download whose SHA-256 matches.

    Parameters
    ----------
    data_dir : path-like
        The data directory (``--data-dir``; the pipeline's ``data_dir``).
    url : str
        URL template with ``{name}`` (default: the pinned release).
    timeout : float
        Seconds per request.

    Returns
    -------
    list of Path
        The checked files.

    Raises
    ------
    DataError
        If a file cannot be downloaded or its SHA-256 is not the pinned one.
    """
    if "{name}" not in url:
        raise DataError(f"the URL template must contain {{name}}, got {url!r}")
    folder = Path(data_dir) / "bottle"
    done = []
    for name, (_, _, digest) in BOTTLE_FILES.items():
        path = folder / name
        if path.is_file() and file_sha256(path) == digest:
            echo(f"{path}: present, SHA-256 ok")
            done.append(path)
            continue
        source = url.format(name=name)
        h = hashlib.sha256()
        try:
            with urllib.request.urlopen(source, timeout=timeout) as response, atomic_write(path) as fh:
                for block in iter(lambda: response.read(1 << 20), b""):
                    h.update(block)
                    fh.write(block)
                if h.hexdigest() != digest:
                    raise DataError(f"{source}: SHA-256 {h.hexdigest()} is not the pinned {digest}; "
                                    "refusing the file (nothing written)")
        except urllib.error.URLError as exc:  # HTTPError included
            raise DataError(f"cannot download {source}: {exc}") from exc
        except (OSError, TimeoutError) as exc:
            raise DataError(f"cannot download {source}: {exc}") from exc
        echo(f"{path}: downloaded, SHA-256 ok")
        done.append(path)
    return done
