"""One figure helper: fixed sizes, PNG + PDF, paths relative to the task output."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
from matplotlib.figure import Figure

#: width, height in inches per panel; figures are panels * this size
PANEL_SIZE = (4.0, 3.2)
DPI = 150

COLORS = {
    "truth": "0.35",
    "neural_ode": "#1f77b4",
    "feedback": "#d62728",
    "feedback_nodecay": "#ff7f0e",
    "luenberger": "#2ca02c",
    "kalman": "#9467bd",
}


def new_figure(nrows: int = 1, ncols: int = 1, **subplot_kw) -> tuple[Figure, object]:
    """A figure of ``nrows x ncols`` panels at the fixed panel size."""
    w, h = PANEL_SIZE
    fig, axes = plt.subplots(nrows, ncols, figsize=(w * ncols, h * nrows), squeeze=False,
                             layout="constrained", **subplot_kw)
    return fig, (axes[0, 0] if nrows == ncols == 1 else axes)


def save_figure(fig: Figure, out_dir: str | Path, name: str) -> str:
    """Save ``fig`` as ``<out_dir>/figures/<name>.png`` and ``.pdf``.

    Returns the PNG path relative to ``out_dir`` (what a results JSON records).
    """
    if not name or "/" in name or name.endswith((".png", ".pdf")):
        raise ValueError(f"figure name must be a bare stem like 'fig4f_multistep', got {name!r}")
    fig_dir = Path(out_dir) / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    fig.savefig(fig_dir / f"{name}.png", dpi=DPI)
    fig.savefig(fig_dir / f"{name}.pdf")
    return f"figures/{name}.png"
