"""The report's figures (matplotlib, Agg backend, PNG files): time against error, error over frames."""

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
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def over_frames(df: pd.DataFrame, path: Path, *, metric: str, title: str = "") -> Path:
    """One line per entry: ``metric`` over the frames of a sequence (mean over seeds)."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 3.6), dpi=100)
    for entry, g in df.groupby("entry", sort=True):
        per_frame = g.groupby("frame")[metric].mean()
        ax.plot(per_frame.index, per_frame.to_numpy(), marker=".", label=entry)
    ax.set_xlabel("frame")
    ax.set_ylabel(metric)
    ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="best", ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def heat_map(values: np.ndarray, path: Path, *, label: str, vmax: float | None = None) -> Path:
    """A per-pixel map with a colour bar (e.g. relMSE), as a PNG."""
    plt = _pyplot()
    h, w = values.shape
    fig, ax = plt.subplots(figsize=(max(3.0, 4.0 * w / max(h, 1)), 3.2), dpi=100)
    image = ax.imshow(values, cmap="inferno", vmin=0.0, vmax=vmax if vmax else float(np.nanmax(values) or 1.0))
    ax.set_axis_off()
    fig.colorbar(image, ax=ax, label=label, fraction=0.046, pad=0.04)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


__all__ = ["heat_map", "over_frames", "time_against_error"]
