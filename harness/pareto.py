"""Run time against error: Pareto fronts and the best configuration within a frame budget.

A **configuration** is a filter with its parameters, preset and backend at a number of samples
per pixel. Its point is (time, error): the time of a frame at a real resolution and its score
on an error metric. Time is the filter's per-frame time plus, where the table has it, the
renderer's own cost of a frame at that spp (equal-time comparison: more samples cost render
time, a better filter costs filter time; an adaptive filter's extra samples are already inside
its own timed calls).

The renderer's cost per spp comes from :mod:`harness.render_cost`; a filter's time from the
``ms_1280x720`` column of the rows the run timed at that real resolution, at the
configuration's own spp (a run times every configuration at each of its spp,
:func:`harness.plan.timing_groups`).

A configuration is on the **front** when no other one is at most as slow and at most as wrong,
and strictly better in one of the two. Along the front, going right (more time) always buys a
better error: the front is monotone by construction.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from harness.results import entry_labels

#: budgets (ms per frame) of the best-within-budget answer when none is given
DEFAULT_BUDGETS = (16.0, 33.0)


def pareto_front(points: pd.DataFrame, time: str = "time_ms", error: str = "error",
                 higher_is_better: bool = False) -> pd.DataFrame:
    """The non-dominated rows of ``points``, by increasing time.

    Parameters
    ----------
    points : DataFrame
        One row per configuration with a ``time`` and an ``error`` column (rows with NaN in
        either are left out).
    time, error : str
        Column names.
    higher_is_better : bool
        Direction of the error column (e.g. SSIM).

    Returns
    -------
    DataFrame
        The front's rows, time increasing and error strictly improving from row to row.
    """
    valid = points.dropna(subset=[time, error])
    if valid.empty:
        return valid
    badness = -valid[error] if higher_is_better else valid[error]
    order = np.lexsort((badness.to_numpy(), valid[time].to_numpy()))  # by time, then best error first
    keep, best = [], math.inf
    for i in order:
        b = float(badness.iloc[i])
        if b < best:
            keep.append(i)
            best = b
    return valid.iloc[keep].reset_index(drop=True)


def configuration_points(df: pd.DataFrame, metric: str, task: str, scene: str | None = None,
                         resolution=(1280, 720), render_cost: pd.DataFrame | None = None) -> pd.DataFrame:
    """One point per configuration of a task: its error on ``metric`` and its time per frame.

    Parameters
    ----------
    df : DataFrame
        A results table.
    metric : str
        The error metric (its score: mean over scenes of the per-scene means).
    task : str
    scene : str, optional
        Only this scene (default: every scene, the overall point).
    resolution : (width, height) or None
        The real resolution whose timings are used (its ``ms_WxH`` column); None: each scene's
        own resolution (``ms_median``; for runs timed at no real resolution), see
        :func:`time_resolution`.
    render_cost : DataFrame, optional
        The renderer's cost per frame (:mod:`harness.render_cost`): its ``render_ms`` at the
        same task, resolution and spp is added to the filter's time.

    Returns
    -------
    DataFrame
        Columns ``entry``, ``filter``, ``preset``, ``params``, ``backend``, ``spp``, ``error``,
        ``filter_ms`` (median per-frame filter time at ``resolution`` on input of the
        configuration's spp; ``filter_ms_spp`` is the spp it was timed at: the same, unless
        that timing is missing (a failed timing, a table of an older harness that timed the
        lowest spp only), where the time at the nearest timed spp stands in),
        ``render_ms`` (NaN where not measured) and ``time_ms`` (their sum, or the filter's
        time alone where the render time is unknown), sorted by time.
    """
    columns = ["entry", "filter", "preset", "params", "backend", "spp", "error", "filter_ms", "filter_ms_spp",
               "render_ms", "time_ms"]
    ok = df[(df.status == "ok") & (df.task == task)]
    if ok.empty or metric not in ok:
        return pd.DataFrame(columns=columns)
    ok = ok.assign(entry=entry_labels(ok))
    if resolution is None:
        sizes = ok[["width", "height"]].drop_duplicates()
        w, h = (int(sizes.width.iloc[0]), int(sizes.height.iloc[0])) if len(sizes) == 1 else (-1, -1)
        timed = _filter_times(ok, "ms_median")
    else:
        w, h = resolution
        timed = _filter_times(ok, f"ms_{w}x{h}")
    render = _render_times(render_cost, task, w, h)
    if scene is not None:
        ok = ok[ok.scene == scene]
    rows = []
    for (entry, filt, preset, params, backend, spp), g in ok.groupby(
            ["entry", "filter", "preset", "params", "backend", "spp"], sort=True):
        scored = g.dropna(subset=[metric])
        error = scored.groupby("scene")[metric].mean().mean() if len(scored) else math.nan
        by_spp = timed.get((filt, preset, params, backend), {})
        at = int(spp) if int(spp) in by_spp else (min(by_spp, key=lambda s: abs(s - int(spp))) if by_spp else -1)
        filter_ms = by_spp.get(at, math.nan)
        render_ms = render.get(int(spp), math.nan)
        total = filter_ms + (render_ms if np.isfinite(render_ms) else 0.0)
        rows.append({"entry": entry, "filter": filt, "preset": preset, "params": params, "backend": backend,
                     "spp": int(spp), "error": error, "filter_ms": filter_ms, "filter_ms_spp": at,
                     "render_ms": render_ms, "time_ms": total})
    if not rows:
        return pd.DataFrame(columns=columns)
    return pd.DataFrame(rows, columns=columns).sort_values("time_ms", kind="stable").reset_index(drop=True)


def _filter_times(ok: pd.DataFrame, column: str) -> dict:
    """(filter, preset, params, backend) -> {spp: median ms} over the rows timed at a real resolution."""
    if column not in ok:
        return {}
    timed = ok.dropna(subset=[column])
    out: dict = {}
    for (filt, preset, params, backend, spp), g in timed.groupby(["filter", "preset", "params", "backend", "spp"]):
        out.setdefault((filt, preset, params, backend), {})[int(spp)] = float(g[column].median())
    return out


def _render_times(render_cost: pd.DataFrame | None, task: str, width: int, height: int) -> dict:
    """spp -> the renderer's median ms per frame for a task at a resolution."""
    if render_cost is None or render_cost.empty:
        return {}
    mine = render_cost[(render_cost.task == task) & (render_cost.width == width) & (render_cost.height == height)]
    return {int(spp): float(g.render_ms.median()) for spp, g in mine.groupby("spp")}


def time_resolution(df: pd.DataFrame, preferred=(1280, 720)):
    """The resolution a table's time-against-error points use: ``preferred`` where the run timed
    filters there, else None (each scene's own resolution)."""
    column = f"ms_{preferred[0]}x{preferred[1]}"
    return tuple(preferred) if column in df and df[column].notna().any() else None


def resolution_label(resolution) -> str:
    """``1280x720`` or ``each scene's resolution``."""
    return f"{resolution[0]}x{resolution[1]}" if resolution else "each scene's resolution"


def best_within(points: pd.DataFrame, budgets=DEFAULT_BUDGETS, time: str = "time_ms", error: str = "error",
                higher_is_better: bool = False) -> pd.DataFrame:
    """For each budget, the configuration with the best error whose time is within it.

    Returns
    -------
    DataFrame
        One row per budget: ``budget_ms`` and the chosen row's columns (NaN where nothing
        fits the budget).
    """
    rows = []
    valid = points.dropna(subset=[time, error])
    for budget in budgets:
        fits = valid[valid[time] <= budget]
        if fits.empty:
            rows.append({"budget_ms": float(budget)})
            continue
        pick = fits[error].idxmax() if higher_is_better else fits[error].idxmin()
        rows.append({"budget_ms": float(budget), **fits.loc[pick].to_dict()})
    return pd.DataFrame(rows)


__all__ = ["DEFAULT_BUDGETS", "best_within", "configuration_points", "pareto_front", "resolution_label",
           "time_resolution"]
