"""One figure helper: fixed sizes, PNG (PDF on request), paths relative to the task output."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

#: width, height in inches per panel; figures are panels * this size
PANEL_SIZE = (4.0, 3.2)
#: pixels per inch of a saved figure
DPI = 150
#: pixels per inch at which a notebook shows a saved figure (the inline backend's size)
SHOW_DPI = 100

#: one colour per model or observer, the same in every figure
COLORS = {
    "truth": "0.35",
    "neural_ode": "#1f77b4",
    "feedback": "#d62728",
    "feedback_nodecay": "#ff7f0e",
    "luenberger": "#2ca02c",
    "kalman": "#9467bd",
}


def new_figure(nrows: int = 1, ncols: int = 1, **subplot_kw) -> tuple[Figure, object]:
    """A figure of ``nrows x ncols`` panels at the fixed panel size.

    The figure is not registered with pyplot, so a notebook shows it once, complete, when
    :func:`save_figure` saves it (the inline backend would show it at the end of the cell that created
    it, without the panels later cells draw).
    """
    w, h = PANEL_SIZE
    fig = Figure(figsize=(w * ncols, h * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **subplot_kw)
    return fig, (axes[0, 0] if nrows == ncols == 1 else axes)


def _in_kernel() -> bool:
    """Whether this runs in a Jupyter kernel (papermill, nbval, a notebook)."""
    try:
        from IPython import get_ipython  # noqa: PLC0415 (IPython is there whenever a kernel is)
    except ImportError:
        return False
    return getattr(get_ipython(), "kernel", None) is not None


def save_figure(fig: Figure, out_dir: str | Path, name: str, *, pdf: bool = False) -> str:
    """Save ``fig`` as ``<out_dir>/figures/<name>.png`` (at :data:`DPI`) and, with ``pdf=True``, also as a
    vector ``.pdf`` (about as costly again as the PNG: the notebooks leave it off; the book shows the PNG).

    In a Jupyter kernel the saved PNG is also what the notebook shows, at :data:`SHOW_DPI` pixels per
    inch (one drawing fewer than the inline backend's).

    Returns the PNG path relative to ``out_dir`` (what a results JSON records).
    """
    if not name or "/" in name or name.endswith((".png", ".pdf")):
        raise ValueError(f"figure name must be a bare stem like 'fig4f_multistep', got {name!r}")
    fig_dir = Path(out_dir) / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    fig.savefig(fig_dir / f"{name}.png", dpi=DPI)
    if pdf:
        fig.savefig(fig_dir / f"{name}.pdf")
    if _in_kernel():
        from IPython.display import Image, display  # noqa: PLC0415

        display(Image(filename=str(fig_dir / f"{name}.png"), width=round(fig.get_figwidth() * SHOW_DPI)))
    return f"figures/{name}.png"


def plot_rate_curve(ax, f_true, f_est, *, title: str, label: str = "model", vmax: float | None = None):
    """Change-rate curve in the (x_dot, y_dot) plane, as in Fig. 4c-e.

    The truth is dashed grey; the estimate is coloured by its 2-norm error;
    stars mark the start. ``f_true``, ``f_est``: arrays of shape (T, 2).
    Returns the colour-mapped line (for a colour bar).
    """
    f_true, f_est = np.asarray(f_true), np.asarray(f_est)
    err = np.linalg.norm(f_est - f_true, axis=-1)
    ax.plot(f_true[:, 0], f_true[:, 1], "--", color=COLORS["truth"], lw=1.2, label="truth")
    seg = np.stack([f_est[:-1], f_est[1:]], axis=1)
    lc = LineCollection(seg, cmap="viridis", norm=plt.Normalize(0, vmax or float(err.max()) or 1.0))
    lc.set_array(err[:-1])
    lc.set_linewidth(1.8)
    ax.add_collection(lc)
    ax.plot(*f_true[0], "*", color=COLORS["truth"], ms=10)
    ax.plot(*f_est[0], "*", color=COLORS["feedback"], ms=10, label=f"{label} (start)")
    ax.set_xlabel(r"$\dot x$")
    ax.set_ylabel(r"$\dot y$")
    ax.set_title(title)
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.legend(loc="lower right", fontsize=8)
    return lc


def trajectory_grid(n: int, ncols: int = 3) -> tuple[Figure, list]:
    """A figure with one panel per trajectory (``ncols`` per row); unused panels are hidden.

    Returns the figure and the list of the ``n`` panels in order.
    """
    if int(n) < 1:
        raise ValueError(f"need at least one trajectory, got n={n}")
    ncols = min(int(ncols), int(n))
    fig, axes = new_figure(-(-int(n) // ncols), ncols)
    flat = list(axes.flat)
    for ax in flat[int(n):]:
        ax.axis("off")
    return fig, flat[: int(n)]
