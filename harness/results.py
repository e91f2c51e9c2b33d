"""Results tables: reading and writing them, the per-scene summary and the leaderboard.

The columns of a results table are defined once, in :mod:`harness.rows` (``Row``). The
leaderboard ranks entries by one metric (:data:`RANK_BY` by default), with 95% intervals and
paired tests between neighbours (:mod:`harness.statistics`, docs/statistics.md), and shows the
filters' times at real resolutions. A table with scenes of both tiers (``procedural``, ``real``)
gets one leaderboard per tier (:func:`tier_boards`) and the rank agreement between them, Kendall's
tau per metric (:func:`rank_agreement`).
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from harness.cache import atomic_write_bytes
from harness.rows import PER_FRAME_SUFFIX, REAL_RESOLUTIONS, combine, metric_columns, timing_column
from harness.specs import TIERS
from harness.statistics import CELL_KEYS, RESAMPLES, interval, kendall_tau, paired

#: the metric leaderboards rank by when it is scored (display-referred, comparable to the paper's RMSE)
RANK_BY = "display_rmse"
#: the real-resolution time columns
TIME_COLUMNS = [timing_column(w, h) for w, h in REAL_RESOLUTIONS]


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
    """Per (task, tier, scene, filter, preset, backend, spp): metric means over frames and seeds, times, statuses.

    ``ms_median`` is the median per-frame time at the scene's (quality) resolution;
    ``ms_1280x720`` and ``ms_1920x1080`` the real-resolution timings where this scene was the
    timing scene; ``reference_noise`` the mean noise floor of its references.
    """
    metrics = metric_columns(df)
    keys = ["task", "tier", "scene", "filter", "preset", "backend", "spp"]
    rows = []
    for key, g in df.groupby(keys, sort=True, dropna=False):
        ok = g[g.status == "ok"]
        row = dict(zip(keys, key))
        for m in metrics:
            row[m] = ok[m].mean() if len(ok) and ok[m].notna().any() else math.nan
        row["ms_median"] = ok["ms_median"].median() if len(ok) else math.nan
        for column in (*TIME_COLUMNS, "reference_noise"):
            row[column] = ok[column].mean() if len(ok) and ok[column].notna().any() else math.nan
        row["spp_used"] = ok["samples_used"].sum() / max(1, (ok["width"] * ok["height"]).sum()) if len(ok) else math.nan
        row["frames"] = len(ok)
        bad = g[g.status != "ok"]
        row["status"] = "ok" if bad.empty else ", ".join(f"{n} {s}" for s, n in bad.status.value_counts().items())
        rows.append(row)
    return pd.DataFrame(rows)


def entry_labels(df: pd.DataFrame) -> pd.Series:
    """A leaderboard entry name per row: ``filter[preset]/backend``, plus ``name=value`` of the
    parameters that differ where one filter ran with several (a sweep), and ``@Nspp`` where the
    table has several spp. An entry that ran a degraded mode (its ``guides`` name missing ones) is
    marked ``[without X,Y]``, plus the guides it derived in their place (``; motion(camera)``),
    so it is never pooled or confused with the full filter or with another degraded mode."""
    label = df["filter"] + df["preset"].map(lambda p: f"[{p}]" if p else "") + "/" + df["backend"]
    if "guides" in df:
        label = label + df["guides"].fillna("").map(_mode)
    for _, params in df.groupby("filter")["params"]:
        if params.nunique() > 1:
            label.loc[params.index] = label.loc[params.index] + " " + _varying(params)
    if df["spp"].nunique() > 1:
        label = label + df["spp"].map(lambda n: f" @{n}spp")
    return label


def _mode(guides: str) -> str:
    """The degraded mode named by a ``guides`` value: ``" [without X,Y]"``, with ``"; a(b)"``
    for guides derived in place of missing ones (named ``channel(source)``); "" for the full filter."""
    if "; without" not in guides:
        return ""
    used, missing = guides.split("; ", 1)
    derived = [g for g in used.split(",") if "(" in g]
    return f" [{missing}" + (f"; {','.join(derived)}" if derived else "") + "]"


def _varying(params: pd.Series) -> pd.Series:
    """``name=value`` of the parameters whose values differ among ``params`` (canonical JSON strings)."""
    parsed = {p: json.loads(p) for p in params.unique()}
    keys = sorted({k for d in parsed.values() for k in d})
    varying = [k for k in keys if len({json.dumps(d.get(k), sort_keys=True) for d in parsed.values()}) > 1]

    def text(value) -> str:
        return value if isinstance(value, str) else json.dumps(value, sort_keys=True)

    return params.map(lambda p: " ".join(f"{k}={text(parsed[p].get(k))}" for k in varying))


def rank_metric(metrics, rank_by: str | None = None) -> str:
    """The metric a leaderboard ranks by: ``rank_by`` (which must be scored), else :data:`RANK_BY`
    where scored, else the first metric in name order."""
    metrics = list(metrics)
    if rank_by is not None:
        if rank_by not in metrics:
            raise ValueError(f"cannot rank by {rank_by!r}: the table scores {sorted(metrics)}")
        return rank_by
    if RANK_BY in metrics:
        return RANK_BY
    if not metrics:
        raise ValueError("the table has no scored metric to rank by")
    return sorted(metrics)[0]


def _cells(g: pd.DataFrame, metric: str) -> pd.DataFrame:
    cells = g[[*CELL_KEYS, metric]].dropna(subset=[metric]).rename(columns={metric: "value"})
    return cells.groupby(CELL_KEYS, as_index=False)["value"].mean()


def column_spec(metric_specs: dict, column: str):
    """The spec of a metric column: the metric's, or for a per-frame column
    (:func:`harness.rows.per_frame_column`) its sequence metric's; None when unknown."""
    if column in metric_specs:
        return metric_specs[column]
    if column.endswith(PER_FRAME_SUFFIX):
        return metric_specs.get(column[: -len(PER_FRAME_SUFFIX)])
    return None


def tiers(df: pd.DataFrame) -> list[str]:
    """The tiers of a table's ``ok`` rows, in :data:`harness.TIERS` order ("" for rows stored without one, last)."""
    present = set(df.loc[df.status == "ok", "tier"]) if "tier" in df and len(df) else set()
    return [t for t in TIERS if t in present] + sorted(present - set(TIERS))


def tier_boards(df: pd.DataFrame, metric_specs: dict,
                rank_by: str | None = None) -> list[tuple[str, str, pd.DataFrame]]:
    """``(task, tier, board)``: the :func:`leaderboard` of each tier of each task, tiers in :func:`tiers` order.

    Each board ranks by the metric the whole table ranks by, and keeps :func:`leaderboard`'s
    attributes (``rank_by``, ``higher_is_better``) without its ``task`` column.
    """
    ok = df[df.status == "ok"]
    metrics = [m for m in metric_columns(df) if ok[m].notna().any()]
    if ok.empty or not metrics:
        return []
    rank_by = rank_metric(metrics, rank_by)
    out = []
    for tier in tiers(df):
        board = leaderboard(df[df["tier"] == tier], metric_specs, rank_by)
        for task, part in board.groupby("task", sort=True) if not board.empty else ():
            part = part.drop(columns="task").reset_index(drop=True)
            part.attrs.update(board.attrs)
            out.append((task, tier, part))
    order = {t: k for k, t in enumerate(sorted({task for task, _, _ in out}))}
    return sorted(out, key=lambda item: order[item[0]])


def rank_agreement(boards: list[tuple[str, str, pd.DataFrame]]) -> pd.DataFrame:
    """Kendall's tau-b between the tiers' rankings, per task and metric.

    For each task with boards of at least two tiers (``boards``: :func:`tier_boards`), each pair
    of tiers and each metric: ``tau`` of the entries' scores on the two tiers' leaderboards (the
    same direction on both, so tau of scores is tau of ranks), over the entries scored on both
    (``filters``: how many; tau needs 2). Rows: ``task``, ``tiers`` ("procedural vs real"),
    ``metric``, ``tau``, ``filters``. Empty for a table of one tier.
    """
    rows = []
    for task in sorted({task for task, _, _ in boards}):
        mine = [(tier, board) for t, tier, board in boards if t == task]
        for a in range(len(mine)):
            for b in range(a + 1, len(mine)):
                (tier_a, first), (tier_b, second) = mine[a], mine[b]
                both = first.merge(second, on="entry", suffixes=("_a", "_b"))
                metrics = [c[: -len("_lo")] for c in first.columns if c.endswith("_lo") and c[:-3] in second]
                for metric in metrics:
                    pairs = both[[f"{metric}_a", f"{metric}_b"]].dropna()
                    rows.append({"task": task, "tiers": f"{tier_a or 'unrecorded'} vs {tier_b or 'unrecorded'}",
                                 "metric": metric, "tau": kendall_tau(pairs.iloc[:, 0], pairs.iloc[:, 1]),
                                 "filters": len(pairs)})
    return pd.DataFrame(rows, columns=["task", "tiers", "metric", "tau", "filters"])


def leaderboard(df: pd.DataFrame, metric_specs: dict, rank_by: str | None = None) -> pd.DataFrame:
    """Entries ranked by one metric, with 95% intervals and paired tests, one board per task.

    Parameters
    ----------
    df : DataFrame
        A results table.
    metric_specs : mapping name -> MetricSpec
        Direction of each metric (without a spec: lower is better) and its noise-floor column.
    rank_by : str, optional
        The metric to rank by (default :func:`rank_metric`).

    Returns
    -------
    DataFrame
        Per task, entries best first: ``rank``, ``entry``, for every metric its score (mean
        over scenes of per-scene means) with ``<metric>_lo``/``<metric>_hi`` (95% bootstrap
        interval, :mod:`harness.statistics`), ``vs_next`` (the paired test against the next
        entry on the ranking metric: ``better``, ``not significant`` or ``not resolved`` when
        the difference is below the references' noise floor, with the p-value), ``p_next``,
        the real-resolution times (``ms_1280x720``, ``ms_1920x1080``), ``timed_on`` (only when
        the rows were timed on several machine setups: each entry's), ``scenes`` and
        ``cells`` (scene x seed x frame values of the ranking metric). ``attrs["rank_by"]``
        names the ranking metric.
    """
    ok = df[df.status == "ok"]
    metrics = [m for m in metric_columns(df) if ok[m].notna().any()]
    if ok.empty or not metrics:
        return pd.DataFrame()
    rank_by = rank_metric(metrics, rank_by)
    spec = column_spec(metric_specs, rank_by)
    higher = getattr(spec, "higher_is_better", False)
    floor_column = getattr(spec, "noise_floor", "")
    ok = ok.assign(entry=entry_labels(ok))
    multiple_setups = len(timing_setups(df)) > 1
    boards = []
    for task, part in ok.groupby("task", sort=True):
        rows, cells = [], {}
        for entry, g in part.groupby("entry", sort=True):
            row = {"task": task, "entry": entry}
            for m in metrics:
                iv = interval(_cells(g, m))
                row[m], row[f"{m}_lo"], row[f"{m}_hi"] = iv.mean, iv.low, iv.high
            cells[entry] = _cells(g, rank_by)
            if floor_column in g:
                cells[entry] = cells[entry].merge(_floor(g, floor_column), on=CELL_KEYS, how="left")
            for column in TIME_COLUMNS:
                row[column] = g[column].median() if g[column].notna().any() else math.nan
            if multiple_setups:  # rows timed on different machines: say which, entry by entry
                row["timed_on"] = "; ".join(sorted(set(_setup_labels(g))))
            row["scenes"] = int(cells[entry]["scene"].nunique())
            row["cells"] = len(cells[entry])
            rows.append(row)
        board = pd.DataFrame(rows).sort_values(rank_by, ascending=not higher, na_position="last", kind="stable")
        board = board.reset_index(drop=True)
        board.insert(1, "rank", np.arange(1, len(board) + 1))
        verdicts, ps = [], []
        for a, b in zip(board["entry"], list(board["entry"][1:]) + [None]):
            if b is None:
                verdicts.append("")
                ps.append(math.nan)
                continue
            verdict, p = _compare(cells[a], cells[b], floor_column)
            verdicts.append(verdict)
            ps.append(p)
        board["vs_next"], board["p_next"] = verdicts, ps
        boards.append(board)
    out = pd.concat(boards, ignore_index=True)
    ordered = ["task", "rank", "entry", rank_by, f"{rank_by}_lo", f"{rank_by}_hi", "vs_next", "p_next"]
    for m in metrics:
        if m != rank_by:
            ordered += [m, f"{m}_lo", f"{m}_hi"]
    out = out[ordered + [*TIME_COLUMNS, *(["timed_on"] if multiple_setups else []), "scenes", "cells"]]
    out.attrs["rank_by"] = rank_by
    out.attrs["higher_is_better"] = higher
    return out


def _floor(g: pd.DataFrame, column: str) -> pd.DataFrame:
    return g.groupby(CELL_KEYS, as_index=False)[column].mean().rename(columns={column: "floor"})


def _compare(first: pd.DataFrame, second: pd.DataFrame, floor_column: str) -> tuple[str, float]:
    """The verdict of a paired test of two neighbouring entries, and its p-value."""
    test = paired(first[[*CELL_KEYS, "value"]], second[[*CELL_KEYS, "value"]])
    if test.cells == 0:
        return "no common cells", math.nan
    if test.cells == 1:
        return "one input: no test", math.nan
    verdict = f"better (p{_p(test.p_value)})" if test.significant else f"not significant (p{_p(test.p_value)})"
    if "floor" in first:
        floor = first.merge(second[CELL_KEYS], on=CELL_KEYS)["floor"].mean()
        if np.isfinite(floor) and abs(test.difference) < floor:
            verdict += f"; not resolved: |diff| {abs(test.difference):.2g} < reference noise {floor:.2g}"
    return verdict, test.p_value


def _p(p: float) -> str:
    return f"<{1 / RESAMPLES:.0e}" if p == 0 else f"={p:.2g}"


def board_table(board: pd.DataFrame, metrics=None, intervals: str = "all") -> pd.DataFrame:
    """A leaderboard as strings: metrics as ``mean [low, high]``, times in ms.

    Parameters
    ----------
    board : DataFrame
        One task's rows of :func:`leaderboard`.
    metrics : list of str, optional
        Metrics to show (default: all of the board's, the ranking one first).
    intervals : {"all", "rank"}
        Intervals for every metric, or for the ranking metric only (the others as means).
    """
    rank_by = board.attrs.get("rank_by")
    known = [c[:-3] for c in board.columns if c.endswith("_lo")]
    metrics = list(metrics or known)
    if rank_by in metrics:
        metrics.remove(rank_by)
        metrics.insert(0, rank_by)
    out = pd.DataFrame({"rank": board["rank"].astype(int), "entry": board["entry"]})
    for m in metrics:
        if intervals == "all" or m == rank_by:
            out[m] = [_with_interval(v, lo, hi, n) for v, lo, hi, n in
                      zip(board[m], board[f"{m}_lo"], board[f"{m}_hi"], board["cells"])]
        else:
            out[m] = board[m].map(lambda v: _format_float(v, "{:.4g}"))
        if m == rank_by:
            out["vs next"] = board["vs_next"]
    for column in TIME_COLUMNS:
        out[column] = board[column].map(lambda v: _format_float(v, "{:.4g}"))
    if "timed_on" in board:
        out["timed_on"] = board["timed_on"]
    out["scenes"] = board["scenes"]
    out["cells"] = board["cells"]
    return out


def _with_interval(value, low, high, cells=2) -> str:
    if value is None or not np.isfinite(value):
        return "-"
    if cells == 1:  # one scene, seed and frame (a captured frame): nothing to resample
        return f"{value:.4g} (one input: no interval)"
    if not (np.isfinite(low) and np.isfinite(high)) or low == high:
        return f"{value:.4g}"
    return f"{value:.4g} [{low:.4g}, {high:.4g}]"


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
