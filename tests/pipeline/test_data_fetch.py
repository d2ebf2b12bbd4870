"""`fnn-pipeline data fetch` (pooch) against HTTP servers on 127.0.0.1: a source that lacks the files, a
corrupt file, no server at all, and the sources tried in order."""

from __future__ import annotations

import hashlib
import socket
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
def www(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[str, Path]]:
    """Serve tmp_path/www (URL prefix returned); pin the SHA-256 of the GOOD files."""
    root = tmp_path / "www"
    for mirror in ("first", "second"):
        (root / mirror).mkdir(parents=True)
    pinned = {name: ("var", (1, 1, 1), hashlib.sha256(data).hexdigest()) for name, data in GOOD.items()}
    monkeypatch.setattr(fnnbook.data, "BOTTLE_FILES", pinned)
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), partial(_Quiet, directory=str(root)))
    thread = threading.Thread(target=httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{httpd.server_address[1]}", root
    finally:
        httpd.shutdown()
        httpd.server_close()
        thread.join()


def _fetch(data: Path, *urls: str, optional: bool = False) -> int:
    args = ["data", "fetch", "--data-dir", str(data)] + [a for u in urls for a in ("--url", u)]
    return main(args + (["--optional"] if optional else []))


def _put(folder: Path, files: dict[str, bytes]) -> None:
    for name, data in files.items():
        (folder / name).write_bytes(data)


def _empty(folder: Path) -> bool:
    return not folder.exists() or not any(folder.iterdir())  # no file, no temporary file


def test_first_source_missing_second_serves(www: tuple[str, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    url, root = www
    _put(root / "second", GOOD)
    assert _fetch(tmp_path / "data", f"{url}/first/{{name}}", f"{url}/second/{{name}}") == 0
    for name, data in GOOD.items():
        assert (tmp_path / "data" / "bottle" / name).read_bytes() == data
    out = capsys.readouterr()
    assert out.out.count("downloaded from the --url 2, SHA-256 ok") == 2 and out.err == ""  # pooch says nothing
    for name in GOOD:  # already there and right: not downloaded again
        (root / "second" / name).unlink()
    assert _fetch(tmp_path / "data", f"{url}/first/{{name}}") == 0
    assert capsys.readouterr().out.count("present, SHA-256 ok") == 2


def test_corrupt_file_is_refused_and_the_next_source_tried(www: tuple[str, Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    url, root = www
    _put(root / "first", {**GOOD, "Training_dataset.mat": b"training throws, truncat"})
    assert _fetch(tmp_path / "data", f"{url}/first/{{name}}") == 2
    err = capsys.readouterr().err
    assert "cannot download Training_dataset.mat: --url 1 (http://127.0.0.1:" in err
    assert "SHA-256 is not the pinned one, file refused" in err
    assert _empty(tmp_path / "data" / "bottle")
    _put(root / "second", GOOD)  # a good copy further down the list is taken
    assert _fetch(tmp_path / "data", f"{url}/first/{{name}}", f"{url}/second/{{name}}") == 0
    out = capsys.readouterr().out
    assert "Training_dataset.mat: downloaded from the --url 2" in out
    assert "Testing_dataset.mat: downloaded from the --url 1" in out


def test_no_server_is_an_error_or_one_line_with_optional(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as sock:  # a port nothing listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    dead = f"http://127.0.0.1:{port}/{{name}}"
    assert _fetch(tmp_path / "data", dead, dead) == 2
    err = capsys.readouterr().err
    assert err.count("no connection") == 2 and err.startswith("error: cannot download Training_dataset.mat")
    assert _fetch(tmp_path / "data", dead, optional=True) == 0
    out = capsys.readouterr()
    assert out.err == "" and out.out.count("\n") == 1  # one line, and the caller goes on
    assert out.out.startswith("note: going on without the bottle throws") and "'not run: data missing'" in out.out
    assert _empty(tmp_path / "data" / "bottle")


def test_a_source_without_name_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _fetch(tmp_path / "data", "http://127.0.0.1:1/file.mat") == 2
    assert "must be a URL template containing {name}" in capsys.readouterr().err


def test_the_official_release_comes_first_both_pinned() -> None:
    (first, official), (second, review) = fnnbook.data.BOTTLE_SOURCES.items()
    assert (first, second) == ("official release", "review repository")
    assert official.startswith("https://raw.githubusercontent.com/JIAjindou/Feedback-neural-network/"
                               "395154347267c7088fcdcecd89f6df1355758117/irregular_object/Dataset_construction/")
    commit = review.split("/")[5]
    assert review.startswith("https://raw.githubusercontent.com/anonymity-tempo/") and len(commit) == 40
    assert all(url.endswith("/{name}") for url in (official, review))


def test_the_release_networks_land_under_their_release_paths(www: tuple[str, Path], tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    """Nested paths as in the release; a second fetch keeps them (one line); a corrupt copy is refused."""
    url, root = www
    files = {"spiral_curve/trained_model/Neural_ODE_x.pt": b"ode", "quadrotor/log/run/loss_record.npy": b"loss"}
    for name, data in files.items():
        (root / "first" / name).parent.mkdir(parents=True, exist_ok=True)
        (root / "first" / name).write_bytes(data)
    monkeypatch.setattr(fnnbook.data, "RELEASE_FILES", {n: hashlib.sha256(d).hexdigest() for n, d in files.items()})
    lines: list[str] = []
    done = fnnbook.data.fetch_release(tmp_path / "data", sources={"mirror": f"{url}/first/{{name}}"},
                                      echo=lines.append)
    assert [p.read_bytes() for p in done] == list(files.values())
    assert done[0] == tmp_path / "data" / "release" / "spiral_curve" / "trained_model" / "Neural_ODE_x.pt"
    lines.clear()
    fnnbook.data.fetch_release(tmp_path / "data", sources={"mirror": f"{url}/nowhere/{{name}}"}, echo=lines.append)
    assert lines == [f"{tmp_path / 'data' / 'release'}: 2 of 2 files present, SHA-256 ok"]
    (root / "first" / "quadrotor/log/run/loss_record.npy").write_bytes(b"tampered")
    done[1].unlink()
    with pytest.raises(fnnbook.data.DataError, match="SHA-256 is not the pinned one"):
        fnnbook.data.fetch_release(tmp_path / "data", sources={"mirror": f"{url}/first/{{name}}"}, echo=lines.append)
    assert not done[1].exists()


def test_optional_release_fetch_without_network_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(fnnbook.data, "RELEASE_SOURCES", {"nowhere": "http://127.0.0.1:9/{name}"})
    monkeypatch.setattr(fnnbook.data, "BOTTLE_SOURCES", {"nowhere": "http://127.0.0.1:9/{name}"})
    assert main(["data", "fetch", "--data-dir", str(tmp_path), "--release", "--optional"]) == 0
    out = capsys.readouterr().out
    assert out.count("note: going on without the authors' networks") == 1 and "no connection" in out


def test_optional_release_fetch_without_network_leaves_no_empty_folders(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """An empty ``release/.../trained_model/`` looked like a release to the why notebooks: none is left behind."""
    monkeypatch.setattr(fnnbook.data, "RELEASE_SOURCES", {"nowhere": "http://127.0.0.1:9/{name}"})
    monkeypatch.setattr(fnnbook.data, "BOTTLE_SOURCES", {"nowhere": "http://127.0.0.1:9/{name}"})
    (tmp_path / "kept").mkdir()  # a folder that was there before stays
    assert main(["data", "fetch", "--data-dir", str(tmp_path), "--release", "--optional"]) == 0
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["kept"]


def _zip(path: Path, members: dict[str, bytes]) -> None:
    import zipfile  # noqa: PLC0415

    with zipfile.ZipFile(path, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)


def test_the_tanks_file_is_extracted_from_its_archive_and_checked(www: tuple[str, Path], tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The member of the archive is kept when its SHA-256 is the pinned one; a changed member, an archive
    without it and a file that is no archive are refused, each source tried once, in order."""
    url, root = www
    good = b"the benchmark's records"
    monkeypatch.setattr(fnnbook.data, "TANKS_SHA256", hashlib.sha256(good).hexdigest())
    _zip(root / "first" / "changed.zip", {"CascadedTanksFiles/dataBenchmark.mat": b"other records"})
    _zip(root / "first" / "empty.zip", {"CascadedTanksFiles/README.txt": b"no data"})
    (root / "first" / "page.zip").write_bytes(b"<html>not found</html>")
    _zip(root / "second" / "CascadedTanksFiles.zip", {"CascadedTanksFiles/dataBenchmark.mat": good,
                                                      "CascadedTanksFiles/dataBenchmark.csv": b"csv"})
    sources = {"changed": f"{url}/first/changed.zip", "empty": f"{url}/first/empty.zip",
               "page": f"{url}/first/page.zip", "good": f"{url}/second/CascadedTanksFiles.zip"}
    lines: list[str] = []
    path = fnnbook.data.fetch_tanks(tmp_path / "data", sources=sources, echo=lines.append)
    assert path == tmp_path / "data" / "cascaded_tanks" / "dataBenchmark.mat" and path.read_bytes() == good
    assert sorted(p.name for p in path.parent.iterdir()) == ["dataBenchmark.mat"]  # no archive, no other member
    assert lines == [f"{path}: extracted from the archive on good, SHA-256 ok"]
    assert fnnbook.data.fetch_tanks(tmp_path / "data", sources={}, echo=lines.append) == path  # present: kept
    assert lines[-1] == f"{path}: present, SHA-256 ok"
    path.unlink()
    with pytest.raises(fnnbook.data.DataError) as err:
        fnnbook.data.fetch_tanks(tmp_path / "data", sources={k: sources[k] for k in ("changed", "empty", "page")})
    msg = str(err.value)
    assert "changed (" in msg and "SHA-256 is not the pinned one, file refused" in msg
    assert "empty (" in msg and "not in the archive" in msg and "page (" in msg and "not a zip archive" in msg
    assert _empty(tmp_path / "data" / "cascaded_tanks")


def test_optional_tanks_fetch_without_network_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setattr(fnnbook.data, "TANKS_SOURCES", {"nowhere": "http://127.0.0.1:9/CascadedTanksFiles.zip"})
    monkeypatch.setattr(fnnbook.data, "BOTTLE_SOURCES", {"nowhere": "http://127.0.0.1:9/{name}"})
    assert main(["data", "fetch", "--data-dir", str(tmp_path), "--tanks", "--optional"]) == 0
    out = capsys.readouterr().out
    assert out.count("note: going on without the cascaded tanks data") == 1 and "no connection" in out
    assert main(["data", "fetch", "--data-dir", str(tmp_path), "--tanks"]) == 2


def test_the_tanks_archive_comes_from_its_official_hosts() -> None:
    (first, doi), (second, site) = fnnbook.data.TANKS_SOURCES.items()
    assert (first, second) == ("4TU.ResearchData", "nonlinearbenchmark.org")
    assert doi.startswith("https://data.4tu.nl/file/") and site.endswith("/CascadedTanksFiles.zip")
