"""The release counts as present only when every file is there with its published SHA-256; limits on reading."""

from __future__ import annotations

import hashlib
import zipfile
from pathlib import Path

import pytest
from fnnbook import PipelineError, check, load_spec
from fnnlib import release
from fnnlib.release import ReleaseError, read_pickled_module, release_files, release_present

from .nbfactory import MakePipeline, leaf_task, write_notebook

FILES = {"spiral_curve/trained_model/a.pt": b"a", "spiral_curve/trained_model/b.pt": b"b",
         "quadrotor/learned/c.npy": b"c"}


@pytest.fixture
def pinned(monkeypatch: pytest.MonkeyPatch) -> dict[str, bytes]:
    monkeypatch.setattr(release, "RELEASE_FILES", {k: hashlib.sha256(v).hexdigest() for k, v in FILES.items()})
    return FILES


def _put(data: Path, files: dict[str, bytes]) -> None:
    for key, content in files.items():
        (data / "release" / key).parent.mkdir(parents=True, exist_ok=True)
        (data / "release" / key).write_bytes(content)


def test_empty_folders_or_part_of_the_files_are_no_release(tmp_path: Path, pinned: dict[str, bytes]) -> None:
    (tmp_path / "release" / "spiral_curve" / "trained_model").mkdir(parents=True)  # what a failed fetch left
    assert not release_present(tmp_path) and not release_present(tmp_path, "spiral_curve/")
    assert not release_present(None) and not release_present(tmp_path / "nowhere")
    _put(tmp_path, {k: v for k, v in pinned.items() if k.startswith("spiral")})
    assert release_present(tmp_path, "spiral_curve/") and not release_present(tmp_path)
    _put(tmp_path, pinned)
    assert release_present(tmp_path)
    (tmp_path / "release" / "quadrotor" / "learned" / "c.npy").write_bytes(b"tampered")
    assert not release_present(tmp_path, "quadrotor/") and release_present(tmp_path, "spiral_curve/")
    assert release_files(tmp_path, "quadrotor/") == {"quadrotor/learned/c.npy": "changed"}


def test_check_refuses_a_release_file_with_another_sha256(make_pipeline: MakePipeline, tmp_path: Path) -> None:
    write_notebook(tmp_path / "notebooks" / "leaf.ipynb", 'profile = ""\nout_dir = ""\ndata_dir = ""\nvalue = 1\n',
                   "pass")
    spec = load_spec(make_pipeline({"leaf": {**leaf_task(), "products": [], "data": ["release/spiral_curve/"]}}))
    key = next(k for k in release.RELEASE_FILES if k.startswith("spiral_curve/"))
    (tmp_path / "data").mkdir()
    check(spec, "smoke")  # no release: not an error (the task judges ours only)
    _put(tmp_path / "data", {key: b"not the published file"})
    with pytest.raises(PipelineError, match="fails its SHA-256 check"):
        check(spec, "smoke")


def test_the_pickle_reader_refuses_big_files_and_zip_bombs_unread(tmp_path: Path) -> None:
    big = tmp_path / "big.pt"
    with big.open("wb") as fh:
        fh.truncate(release.MAX_PICKLE_BYTES + 1)  # sparse: nothing written
    with pytest.raises(ReleaseError, match="refused unread"):
        read_pickled_module(big)
    bomb = tmp_path / "bomb.pt"
    with zipfile.ZipFile(bomb, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("archive/data.pkl", b"\0" * (release.MAX_PICKLE_BYTES + 1))  # a few KB on disk
    assert bomb.stat().st_size < 100_000
    with pytest.raises(ReleaseError, match="zip bomb"):
        read_pickled_module(bomb)
