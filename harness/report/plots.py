"""The report's figures (matplotlib, Agg backend, PNG files): time against error, error and flicker over frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from harness.pareto import pareto_front


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def time_against_error(points: pd.DataFrame, path: Path, *, metric: str, higher_is_better: bool, budgets=(),
                       title: str = "", resolution: str = "1280x720") -> Path:
    """Every configuration as a point (log time, error), the Pareto front as a line, budgets as vertical lines."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.6), dpi=100)
    valid = points.dropna(subset=["time_ms", "error"])
    for filt, g in valid.groupby("filter", sort=True):
        ax.scatter(g.time_ms, g.error, s=28, label=filt, zorder=3)
    front = pareto_front(valid, "time_ms", "error", higher_is_better)
    if len(front):
        ax.step(front.time_ms, front.error, where="post", color="black", lw=1.2, zorder=2, label="Pareto front")
        for r in front.itertuples():
            ax.annotate(r.entry, (r.time_ms, r.error), fontsize=6, xytext=(3, 3), textcoords="offset points")
    for b in budgets:
        ax.axvline(b, color="grey", ls="--", lw=1)
        ax.text(b, 1.0, f" {b:g} ms", transform=ax.get_xaxis_transform(), fontsize=8, va="top", color="grey")
    if len(valid) and (valid.time_ms > 0).all():
        ax.set_xscale("log")
    rendered = "render_ms" in valid and valid.render_ms.notna().any()
    what = "filter + render at its spp" if rendered else "filter only: no render time in this run"
    ax.set_xlabel(f"time per frame at {resolution}, ms ({what})")
    ax.set_ylabel(f"{metric} ({'higher' if higher_is_better else 'lower'} is better)")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    if len(valid):
        ax.legend(fontsize=7, loc="best")
    else:
        ax.text(0.5, 0.5, "no timed configuration", transform=ax.transAxes, ha="center")
    fig.subplots_adjust(left=0.11, right=0.97, top=0.92, bottom=0.14)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def over_frames(df: pd.DataFrame, path: Path, *, metric: str, flicker=(), title: str = "") -> Path:
    """Error and flicker over the frames of a sequence: one panel per column, one line per entry.

    Parameters
    ----------
    df : DataFrame
        A sequence's rows with an ``entry`` column (values averaged over seeds per frame).
    path : Path
    metric : str
        The error metric of the first panel.
    flicker : iterable of str
        Per-frame columns of sequence metrics (:func:`harness.rows.per_frame_column`), one panel
        each, below the error (their frame 0 has no value: no previous frame).
    title : str
    """
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator

    panels = [metric, *flicker]
    height = 1.0 + 2.6 * len(panels)  # inches: 2.6 per panel, 1.0 for the title and the frame axis
    fig, axes = plt.subplots(len(panels), 1, figsize=(7.5, height), dpi=100, sharex=True, squeeze=False)
    entries = sorted(set(df.entry))
    cmap = plt.get_cmap("tab10" if len(entries) <= 10 else "tab20")
    colours = {entry: cmap(k % cmap.N) for k, entry in enumerate(entries)}
    for ax, column in zip(axes[:, 0], panels):
        for entry, g in df.groupby("entry", sort=True):
            per_frame = g.groupby("frame")[column].mean().dropna() if column in g else pd.Series(dtype=float)
            if len(per_frame):
                ax.plot(per_frame.index, per_frame.to_numpy(), marker=".", color=colours[entry], label=entry)
        ax.set_ylabel(column, fontsize=8)
        ax.grid(True, alpha=0.3)
    axes[0, 0].set_title(title, fontsize=10)
    axes[0, 0].legend(fontsize=7, loc="best", ncol=2)
    axes[-1, 0].xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[-1, 0].set_xlabel("frame")
    fig.subplots_adjust(left=0.11, right=0.97, top=1.0 - 0.4 / height, bottom=0.55 / height, hspace=0.12)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def colour_map(values: np.ndarray, vmax: float, cmap: str = "inferno") -> np.ndarray:
    """Per-pixel values in [0, vmax] as display colours (H, W, 3) in [0, 1] (no figure: fast)."""
    import matplotlib

    scaled = np.clip(np.nan_to_num(np.asarray(values, np.float64) / (vmax or 1.0)), 0.0, 1.0)
    return matplotlib.colormaps[cmap](scaled)[..., :3]


def colour_bar(path: Path, *, vmax: float, label: str, cmap: str = "inferno") -> Path:
    """A horizontal colour bar from 0 to ``vmax`` (the scale of the :func:`colour_map` images beside it)."""
    plt = _pyplot()
    import matplotlib

    fig = plt.figure(figsize=(4.0, 0.75), dpi=100)
    ax = fig.add_axes((0.05, 0.55, 0.9, 0.3))
    fig.colorbar(matplotlib.cm.ScalarMappable(matplotlib.colors.Normalize(0.0, vmax or 1.0), cmap), cax=ax,
                 orientation="horizontal", label=label)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


__all__ = ["colour_bar", "colour_map", "over_frames", "time_against_error"]
