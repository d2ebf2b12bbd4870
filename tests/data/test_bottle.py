"""The bottle loader: checksums, shapes, clear errors; the real files where present."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.io import savemat

from fnnlib.data import BOTTLE_FILES, DataError, bottle_throws, load_bottle, synthetic_throws

ROOT = Path(__file__).resolve().parents[2]
#: the data directory holding the real throws: $FNN_DATA_DIR (CI passes the workspace's), else data/ here
REAL_DIRS = [Path(os.environ["FNN_DATA_DIR"])] if os.environ.get("FNN_DATA_DIR") else [ROOT / "data"]
REAL = next((d for d in REAL_DIRS if all((d / "bottle" / f).is_file() for f in BOTTLE_FILES)), None)


def _write_fake(folder: Path, shapes: dict[str, tuple[int, ...]] | None = None) -> None:
    (folder / "bottle").mkdir(parents=True, exist_ok=True)
    for name, (var, shape, _) in BOTTLE_FILES.items():
        shape = (shapes or {}).get(name, shape)
        savemat(folder / "bottle" / name, {var: np.zeros(shape)})


def test_missing_files_say_where_they_come_from(tmp_path: Path) -> None:
    with pytest.raises(DataError, match=r"missing Training_dataset\.mat, Testing_dataset\.mat.*authors' code"):
        load_bottle(tmp_path)


def test_one_data_choice_for_the_throws(tmp_path: Path) -> None:
    """bottle_throws: synthetic throws drawn with seed and seed + 1, the real ones read (and checked) from data_dir."""
    train, test = bottle_throws("synthetic", data_dir=tmp_path, synthetic_sizes=[3, 2, 40], seed=4)
    for got, want in ((train, synthetic_throws(3, 40, seed=4)), (test, synthetic_throws(2, 40, seed=5))):
        assert torch.equal(got.data, want.data) and got.Ts == want.Ts
    with pytest.raises(DataError, match="missing"):
        bottle_throws("real", data_dir=tmp_path, synthetic_sizes=[3, 2, 40], seed=4)
    with pytest.raises(ValueError, match="data must be one of"):
        bottle_throws("fake", data_dir=tmp_path, synthetic_sizes=[3, 2, 40], seed=4)


def test_a_file_failing_its_checksum_is_refused(tmp_path: Path) -> None:
    _write_fake(tmp_path)
    with pytest.raises(DataError, match="fails its SHA-256 check"):
        load_bottle(tmp_path)


def test_shape_is_checked_when_checksum_is_skipped(tmp_path: Path) -> None:
    _write_fake(tmp_path, {"Testing_dataset.mat": (9, 100, 9)})
    with pytest.raises(DataError, match=r"expected a finite array of shape \(9, 1058, 9\)"):
        load_bottle(tmp_path, verify=False)


def test_a_corrupt_file_is_refused_not_half_read(tmp_path: Path) -> None:
    _write_fake(tmp_path)
    (tmp_path / "bottle" / "Training_dataset.mat").write_bytes(b"not a mat file")
    with pytest.raises(DataError, match="cannot be read as a MATLAB file"):
        load_bottle(tmp_path, verify=False)


def test_synthetic_throws_are_consistent_and_seeded() -> None:
    a, b = synthetic_throws(2, 50, seed=3), synthetic_throws(2, 50, seed=3)
    assert torch.equal(a.data, b.data) and a.data.shape == (2, 50, 9)
    # velocity is the derivative of position (finite differences at 1 ms, O(Ts) agreement)
    dp = torch.diff(a.data[..., 3:6], dim=1) / a.Ts
    assert torch.allclose(dp, a.data[:, :-1, 6:9], atol=5e-2)
    assert a.state.shape == (2, 50, 6) and a.t[1] == pytest.approx(1e-3)


@pytest.mark.skipif(REAL is None, reason="no real throws: set FNN_DATA_DIR to a data directory holding bottle/*.mat")
def test_real_throws_load_with_their_published_checksums(tmp_path: Path) -> None:
    train, test = load_bottle(REAL)
    assert train.data.shape == (21, 1058, 9) and test.data.shape == (9, 1058, 9)
    assert float(train.acc[..., 2].mean()) < -8.0  # z up: gravity dominates the vertical acceleration
    # one changed byte anywhere is refused
    shutil.copytree(REAL / "bottle", tmp_path / "bottle")
    path = tmp_path / "bottle" / "Testing_dataset.mat"
    blob = bytearray(path.read_bytes())
    blob[-100] ^= 0x01
    path.write_bytes(bytes(blob))
    with pytest.raises(DataError, match="SHA-256"):
        load_bottle(tmp_path)
