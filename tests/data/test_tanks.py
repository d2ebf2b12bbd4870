"""The cascaded tanks benchmark: its file checked before use, the synthetic records, the metric and the
published table. The real file is read only when FNN_DATA_DIR names a data directory that holds it."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import torch

from fnnlib.data.bottle import DataError
from fnnlib.data.tanks import (PUBLISHED_RESULTS, TANKS_FILE, load_tanks, simulation_rmse, synthetic_tanks,
                               tanks_records)


@pytest.fixture(scope="module")
def synthetic():
    return synthetic_tanks(seed=0)


def test_synthetic_records_have_the_benchmarks_shape(synthetic) -> None:
    r = synthetic
    for a in (r.u_est, r.y_est, r.u_val, r.y_val):
        assert a.shape == (1024, 1) and a.dtype == torch.float64
    assert r.Ts == 4.0 and r.source == "synthetic" and r.x_est.shape == (1024, 2)
    assert float(r.u_est.min()) == pytest.approx(0.5) and float(r.u_est.max()) == pytest.approx(6.5)
    assert float(r.y_est.max()) <= 10.0 and float(r.y_est.min()) > 1.0
    assert int(r.saturated("est").sum() + r.saturated("val").sum()) > 0  # the overflow happens
    assert not torch.equal(r.u_est, r.u_val) and not torch.equal(r.x_est[0], r.x_val[0])


def test_synthetic_records_are_seeded() -> None:
    a, b = synthetic_tanks(50, seed=3), synthetic_tanks(50, seed=3)
    assert torch.equal(a.y_val, b.y_val) and not torch.equal(a.y_val, synthetic_tanks(50, seed=4).y_val)


def test_noise_free_output_is_the_lower_level(synthetic) -> None:
    r = synthetic_tanks(40, seed=1, noise_std=0.0)
    assert torch.allclose(r.y_est, r.x_est[:, 1:].clamp(max=10.0))


@pytest.mark.parametrize(("kwargs", "match"), [({"n_samples": 5}, "n_samples"), ({"noise_std": -1.0}, "noise_std"),
                                               ({"Ts": 0.0}, "Ts")])
def test_bad_synthetic_settings_are_refused(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        synthetic_tanks(**{"n_samples": 20, **kwargs})


def test_missing_or_changed_file_is_a_data_error(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="fnn-pipeline data fetch --tanks"):
        load_tanks(tmp_path)
    (tmp_path / "cascaded_tanks").mkdir()
    (tmp_path / "cascaded_tanks" / TANKS_FILE).write_bytes(b"not the benchmark")
    with pytest.raises(DataError, match="SHA-256"):
        load_tanks(tmp_path)
    with pytest.raises(DataError, match="cannot be read"):
        load_tanks(tmp_path, verify=False)


def test_records_by_name() -> None:
    assert tanks_records("synthetic", n_samples=30).source == "synthetic"
    with pytest.raises(ValueError, match="data must be one of"):
        tanks_records("simulated")


def test_simulation_rmse_scores_after_the_initial_samples() -> None:
    y = np.array([9.0, 9.0, 1.0, 2.0, 3.0])
    assert simulation_rmse(y, [0.0, 0.0, 1.0, 2.0, 5.0], skip=2) == pytest.approx(np.sqrt(4 / 3))
    with pytest.raises(ValueError, match="skip"):
        simulation_rmse(y, y, skip=5)
    with pytest.raises(ValueError, match="diverged"):
        simulation_rmse([np.nan] * 5, y)
    with pytest.raises(ValueError, match="same length"):
        simulation_rmse(y[:4], y)


def test_every_published_number_names_its_source_and_protocol() -> None:
    assert PUBLISHED_RESULTS
    for r in PUBLISHED_RESULTS:
        assert r.source.startswith("https://") and r.reference and r.protocol and r.metric and r.method
        assert 0 < r.value < 5


@pytest.mark.skipif(not os.environ.get("FNN_DATA_DIR"), reason="FNN_DATA_DIR names no data directory")
def test_the_real_records() -> None:
    data_dir = Path(os.environ["FNN_DATA_DIR"])
    if not (data_dir / "cascaded_tanks" / TANKS_FILE).is_file():
        pytest.skip(f"no cascaded_tanks/{TANKS_FILE} in {data_dir}")
    r = load_tanks(data_dir)
    assert r.y_est.shape == (1024, 1) and r.source == "real" and r.x_est is None
    assert float(r.y_val.max()) == 10.0 and int(r.saturated("val").sum()) > 0
