"""The figure helpers: fixed sizes, PNG + PDF under figures/, relative paths."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from fnnlib.plotting import new_figure, save_figure  # noqa: E402
from fnnlib.plotting import PANEL_SIZE  # noqa: E402


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def test_save_figure_writes_png_and_pdf_on_request(tmp_path):
    fig, ax = new_figure()
    ax.plot([0, 1], [1, 0])
    rel = save_figure(fig, tmp_path, "fig4f_multistep")
    assert rel == "figures/fig4f_multistep.png"
    png, pdf = tmp_path / "figures" / "fig4f_multistep.png", tmp_path / "figures" / "fig4f_multistep.pdf"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not pdf.exists()
    assert save_figure(fig, tmp_path, "fig4f_multistep", pdf=True) == rel
    assert pdf.read_bytes()[:5] == b"%PDF-"
    assert (tmp_path / rel) == png


@pytest.mark.parametrize("name", ["", "sub/fig", "fig.png", "fig.pdf"])
def test_save_figure_rejects_bad_names(tmp_path, name):
    fig, _ = new_figure()
    with pytest.raises(ValueError, match="figure name must be a bare stem"):
        save_figure(fig, tmp_path, name)
    assert not (tmp_path / "figures").exists() or not any((tmp_path / "figures").iterdir())


def test_new_figure_sizes():
    fig, ax = new_figure()
    assert hasattr(ax, "plot")  # a single Axes for 1 x 1
    np.testing.assert_allclose(fig.get_size_inches(), PANEL_SIZE)
    fig, axes = new_figure(2, 3)
    assert axes.shape == (2, 3)
    np.testing.assert_allclose(fig.get_size_inches(), (3 * PANEL_SIZE[0], 2 * PANEL_SIZE[1]))


def test_plot_rate_curve_colours_by_error():
    from fnnlib.plotting import plot_rate_curve

    t = np.linspace(0, 3, 31)
    f_true = np.stack([np.cos(t), np.sin(t)], axis=1)
    f_est = f_true + np.array([0.3, 0.4])  # constant error 0.5
    fig, ax = new_figure()
    lc = plot_rate_curve(ax, f_true, f_est, title="(e)", label="feedback")
    assert len(lc.get_segments()) == 30
    np.testing.assert_allclose(lc.get_array(), 0.5)
    assert ax.get_title() == "(e)"


def test_trajectory_grid_gives_one_panel_per_trajectory() -> None:
    import matplotlib.pyplot as plt

    from fnnlib.plotting import trajectory_grid

    fig, axes = trajectory_grid(5)
    assert len(axes) == 5 and len(fig.axes) == 6  # 2 x 3 grid, last panel hidden
    assert not fig.axes[5].axison
    plt.close(fig)
    with pytest.raises(ValueError, match="at least one"):
        trajectory_grid(0)
