"""Results tables: reading and writing them, the per-scene summary and the leaderboard.

The columns of a results table are defined once, in :mod:`harness.rows` (``Row``).
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pandas as pd

from harness.cache import atomic_write_bytes
from harness.rows import combine, metric_columns


def write_table(df: pd.DataFrame, path: Path) -> None:
    """Write a table as Parquet, atomically."""
    buf = io.BytesIO()
    df.to_parquet(buf, index=False)
    atomic_write_bytes(Path(path), buf.getvalue())


def read_results(out_dir: str | Path) -> pd.DataFrame:
    """Read ``DIR/results.parquet``, or rebuild it from the per-job files of an interrupted run."""
    out_dir = Path(out_dir)
    jobs = sorted((out_dir / "jobs").glob("*.parquet"))
    if jobs:
        return combine([pd.read_parquet(p) for p in jobs])
    path = out_dir / "results.parquet"
    if not path.exists():
        raise FileNotFoundError(f"no results in {out_dir}: neither results.parquet nor jobs/*.parquet")
    return combine([pd.read_parquet(path)])


def summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per (task, scene, filter, preset, backend, spp): mean of each metric, median ms, samples, statuses."""
    metrics = metric_columns(df)
    keys = ["task", "scene", "filter", "preset", "backend", "spp"]
    rows = []
    for key, g in df.groupby(keys, sort=True, dropna=False):
        ok = g[g.status == "ok"]
        row = dict(zip(keys, key))
        for m in metrics:
            row[m] = ok[m].mean() if len(ok) and ok[m].notna().any() else math.nan
        row["ms_median"] = ok["ms_median"].median() if len(ok) else math.nan
        row["spp_used"] = ok["samples_used"].sum() / max(1, (ok["width"] * ok["height"]).sum()) if len(ok) else math.nan
        row["frames"] = len(ok)
        bad = g[g.status != "ok"]
        row["status"] = "ok" if bad.empty else ", ".join(f"{n} {s}" for s, n in bad.status.value_counts().items())
        rows.append(row)
    return pd.DataFrame(rows)


def leaderboard(df: pd.DataFrame, metric_specs: dict) -> pd.DataFrame:
    """Filters ranked by their mean rank over scenes and metrics (best first), one board per task.

    Parameters
    ----------
    df : DataFrame
        A results table.
    metric_specs : mapping name -> MetricSpec
        For the direction of each metric (metrics without a spec count as lower-is-better).

    Returns
    -------
    DataFrame
        Columns ``task``, ``entry`` (filter[preset]/backend), the metrics (means over scenes),
        ``ms_median`` and ``rank``; sorted by task, then rank.
    """
    summ = summary(df[df.status == "ok"])
    if summ.empty:
        return summ
    summ["entry"] = summ["filter"] + summ["preset"].map(lambda p: f"[{p}]" if p else "") + "/" + summ["backend"]
    ranks = []
    for m in metric_columns(df):
        if summ[m].notna().sum() == 0:
            continue
        higher = getattr(metric_specs.get(m), "higher_is_better", False)
        ranks.append(summ.groupby(["task", "scene"])[m].rank(ascending=not higher, method="average"))
    summ["rank"] = pd.concat(ranks, axis=1).mean(axis=1) if ranks else math.nan
    cols = [m for m in metric_columns(df) if summ[m].notna().any()] + ["ms_median", "rank"]
    board = summ.groupby(["task", "entry"])[cols].mean().reset_index()
    setups = timing_setups(df)
    if len(setups) > 1:  # rows timed on different machines: say which, entry by entry
        ok = df[df.status == "ok"].assign(entry=lambda d: d["filter"] + d["preset"].map(
            lambda p: f"[{p}]" if p else "") + "/" + d["backend"], setup=lambda d: _setup_labels(d))
        timed_on = ok.groupby(["task", "entry"])["setup"].agg(lambda v: "; ".join(sorted(set(v))))
        board["timed_on"] = [timed_on.get((t, e), "") for t, e in zip(board["task"], board["entry"])]
    return board.sort_values(["task", "rank"], kind="stable").reset_index(drop=True)


def timing_setups(df: pd.DataFrame) -> list[str]:
    """The distinct ``machine (N threads)`` that timed the ``ok`` rows of a table.

    More than one means the table's times come from different machines (a cluster run): the
    leaderboard then names each entry's in a ``timed_on`` column.
    """
    ok = df[df.status == "ok"]
    return sorted(set(_setup_labels(ok))) if len(ok) else []


def _setup_labels(df: pd.DataFrame) -> pd.Series:
    return df["machine"].astype(str) + " (" + df["threads"].astype(str) + " threads)"


def _format_float(v, floatfmt: str) -> str:
    return "-" if v is None or np.isnan(v) else floatfmt.format(v)


def format_table(df: pd.DataFrame, floatfmt: str = "{:.4g}") -> str:
    """A plain-text table for the terminal."""
    if df.empty:
        return "(no rows)"
    shown = df.copy()
    for c in shown.columns:
        if shown[c].dtype.kind == "f":
            shown[c] = shown[c].map(lambda v: _format_float(v, floatfmt))
    return shown.to_string(index=False)


def to_markdown(df: pd.DataFrame, floatfmt: str = "{:.4g}") -> str:
    """A GitHub-flavoured markdown table."""
    if df.empty:
        return "(no rows)\n"

    def cell(v):
        return _format_float(v, floatfmt) if isinstance(v, float) else str(v).replace("|", "\\|")

    lines = ["| " + " | ".join(map(str, df.columns)) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines) + "\n"
