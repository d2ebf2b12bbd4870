"""`fnn-pipeline data fetch` against a local HTTP server on 127.0.0.1: good, corrupt and missing files."""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Iterator
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

import fnnbook.data
from fnnbook.cli import main

GOOD = {"Training_dataset.mat": b"training throws", "Testing_dataset.mat": b"testing throws"}


class _Quiet(SimpleHTTPRequestHandler):
    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture
def server(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[str, Path]]:
    """Serve tmp_path/www; pin the SHA-256 of the GOOD files."""
    www = tmp_path / "www"
    www.mkdir()
    pinned = {name: ("var", (1, 1, 1), hashlib.sha256(data).hexdigest()) for name, data in GOOD.items()}
    monkeypatch.setattr(fnnbook.data, "BOTTLE_FILES", pinned)
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), partial(_Quiet, directory=str(www)))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}/{{name}}", www
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join()


def _fetch(url: str, data: Path) -> int:
    return main(["data", "fetch", "--data-dir", str(data), "--url", url])


def test_good_files_are_placed_and_kept(server: tuple[str, Path], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    url, www = server
    for name, data in GOOD.items():
        (www / name).write_bytes(data)
    assert _fetch(url, tmp_path / "data") == 0
    for name, data in GOOD.items():
        assert (tmp_path / "data" / "bottle" / name).read_bytes() == data
    assert capsys.readouterr().out.count("downloaded, SHA-256 ok") == 2
    (www / "Training_dataset.mat").unlink()  # already there and right: not downloaded again
    assert _fetch(url, tmp_path / "data") == 0
    assert capsys.readouterr().out.count("present, SHA-256 ok") == 2


def test_corrupt_file_is_refused_and_nothing_is_left(server: tuple[str, Path], tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    url, www = server
    (www / "Training_dataset.mat").write_bytes(b"training throws, truncat")
    (www / "Testing_dataset.mat").write_bytes(GOOD["Testing_dataset.mat"])
    assert _fetch(url, tmp_path / "data") == 2
    assert "is not the pinned" in capsys.readouterr().err
    folder = tmp_path / "data" / "bottle"
    assert not folder.exists() or not any(folder.iterdir())  # no file, no temporary file


def test_missing_file_is_a_clear_error(server: tuple[str, Path], tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    url, _ = server
    assert _fetch(url, tmp_path / "data") == 2
    err = capsys.readouterr().err
    assert "cannot download http://127.0.0.1:" in err and "404" in err


def test_the_default_source_is_pinned() -> None:
    owner, repo, commit = fnnbook.data.BOTTLE_RELEASE.split("/")
    assert len(commit) == 40 and int(commit, 16) >= 0
    assert fnnbook.data.BOTTLE_URL.startswith(f"https://raw.githubusercontent.com/{owner}/{repo}/{commit}/")
