"""The ARX baseline: it recovers a linear system exactly, simulates free-run, and picks orders on its own record."""

from __future__ import annotations

import numpy as np
import pytest

from fnnlib.models.arx import fit_arx, select_arx


def _record(T: int = 400, seed: int = 0, noise: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """y_k = 1.5 y_{k-1} - 0.7 y_{k-2} + 0.2 u_{k-1} + 0.1 u_{k-2} + 0.3 (a stable second-order system)."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=T)
    y = np.zeros(T)
    for k in range(2, T):
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + 0.2 * u[k - 1] + 0.1 * u[k - 2] + 0.3
    return u, y + noise * rng.normal(size=T)


def test_exact_recovery_of_a_linear_system() -> None:
    u, y = _record()
    m = fit_arx(u, y, na=2, nb=2, nk=1)
    np.testing.assert_allclose(m.a, [1.5, -0.7], atol=1e-9)
    np.testing.assert_allclose(m.b, [0.2, 0.1], atol=1e-9)
    assert m.c == pytest.approx(0.3, abs=1e-9) and m.n_init == 2
    u2, y2 = _record(seed=1)
    np.testing.assert_allclose(m.simulate(u2, y2), y2, atol=1e-8)  # free run of the true model is the record


def test_simulation_feeds_back_its_own_output() -> None:
    u, y = _record()
    m = fit_arx(u, y, na=2, nb=2, nk=1)
    y_bad = y.copy()
    y_bad[10:] += 100.0  # measurements after the initial samples are never read
    np.testing.assert_allclose(m.simulate(u, y_bad, n_init=5), y, atol=1e-8)


def test_select_picks_orders_on_the_fitting_record() -> None:
    u, y = _record(noise=0.01)
    m, table = select_arx(u, y, na=range(1, 4), nb=range(1, 4), nk=(0, 1))
    assert len(table) == 18 and min(table.values()) == table[(len(m.a), len(m.b), m.nk)]
    assert len(m.a) >= 2 and min(table.values()) < 0.1


@pytest.mark.parametrize(("kwargs", "match"), [({"na": -1}, "na"), ({"nb": 0}, "nb"), ({"nk": 1.5}, "nk")])
def test_bad_orders_are_refused(kwargs, match) -> None:
    u, y = _record(50)
    with pytest.raises(ValueError, match=match):
        fit_arx(u, y, **{"na": 2, "nb": 2, "nk": 1, **kwargs})


def test_bad_records_are_refused() -> None:
    u, y = _record(50)
    with pytest.raises(ValueError, match="same length"):
        fit_arx(u[:40], y, 2, 2)
    with pytest.raises(ValueError, match="too short"):
        fit_arx(u[:5], y[:5], 2, 2)
    with pytest.raises(ValueError, match="non-finite"):
        fit_arx(np.r_[u[:-1], np.nan], y, 2, 2)
    with pytest.raises(ValueError, match="n_init"):
        fit_arx(u, y, 2, 2).simulate(u, y, n_init=1)
