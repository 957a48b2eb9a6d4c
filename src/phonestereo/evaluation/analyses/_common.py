"""Helpers every chapter-3 analysis shares: figure saving, JSON cleaning, per-corner maps."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

F64 = np.ndarray


def save_figure(fig: Figure, path: Path) -> Path:
    """Render a Matplotlib figure (Agg) to ``path`` (PNG, 110 dpi)."""
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
    return path


def map_panel(fig: Figure, ax: Any, xy: F64, v: F64, title: str, label: str, **kw: Any) -> None:
    """Scatter of per-corner values at their (rectified wide) pixels, with a colour bar."""
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=v, s=10, cmap=kw.pop("cmap", "viridis"), **kw)
    fig.colorbar(sc, ax=ax, label=label)
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("rectified x [px]")
    ax.set_ylabel("rectified y [px]")
    ax.invert_yaxis()
    ax.set_aspect("equal")


def json_clean(v: Any) -> Any:
    """JSON-safe copy: private ``_`` keys dropped, NaN/inf → None, NumPy → Python.

    >>> json_clean({"a": np.float64("nan"), "_big": [1], "b": np.arange(2)})
    {'a': None, 'b': [0, 1]}
    """
    if isinstance(v, dict):
        return {k: json_clean(x) for k, x in v.items() if not str(k).startswith("_")}
    if isinstance(v, list | tuple):
        return [json_clean(x) for x in v]
    if isinstance(v, np.ndarray):
        return json_clean(v.tolist())
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v


__all__ = ["json_clean", "map_panel", "save_figure"]
