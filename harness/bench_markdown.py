"""A bench's tables as markdown, with the command and the machine (``denoise-bench bench --markdown``).

The output is the part of docs/performance.md that a re-run replaces
(``python benchmarks/performance_page.py`` splices it between the page's markers).
"""

from __future__ import annotations

import pandas as pd

from harness.results import to_markdown


def environment_line(environment: dict) -> str:
    """One paragraph: CPU, cores, threads limit, load averages, date, Python and library versions."""
    env = environment
    versions = ", ".join(f"{name} {version}" for name, version in env.get("versions", {}).items())
    return (f"Machine: {env.get('cpu', '?')}, {env.get('cores', '?')} cores (Numba's limit "
            f"{env.get('max_threads', '?')} threads); load average (1 min) {env.get('load_start', '?')} at the "
            f"start, {env.get('load_end', '?')} at the end; {env.get('date', '')}. Python {env.get('python', '?')}"
            + (f"; {versions}" if versions else "") + ".")


def scaling_table(table: pd.DataFrame) -> pd.DataFrame:
    """Median milliseconds per filter (rows) at each resolution and thread count (columns)."""
    ok = table[table["status"] == "ok"]
    if ok.empty:
        return pd.DataFrame()
    order = list(dict.fromkeys(ok["filter"]))
    columns = list(dict.fromkeys(f"{r}, {n}t" for r, n in zip(ok["resolution"], ok["threads"])))
    shown = ok.assign(at=[f"{r}, {n}t" for r, n in zip(ok["resolution"], ok["threads"])])
    pivot = shown.pivot_table(index="filter", columns="at", values="ms_median", aggfunc="first")
    return pivot.reindex(index=order, columns=columns).reset_index()


def stage_lines(stages: pd.DataFrame) -> pd.DataFrame:
    """One row per filter, resolution and thread count: its stages as ``name ms`` in order."""
    keys = ["filter", "resolution", "threads"]
    rows = []
    for record in stages.to_dict("records"):
        named = [f"{k} {_number(v)}" for k, v in record.items() if k not in keys and v == v]
        rows.append({**{k: record[k] for k in keys}, "stages (ms, last timed call)": ", ".join(named)})
    return pd.DataFrame(rows)


def _number(value) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def bench_markdown(result, command: str) -> str:
    """The tables of a :class:`harness.bench.BenchResult` as markdown.

    Parameters
    ----------
    result : harness.bench.BenchResult
    command : str
        The command that produced it (written above the tables).
    """
    table = result.table
    shown = table.drop(columns=[c for c in ("notes",) if c in table and not table[c].astype(bool).any()])
    parts = [f"Command: `{command}`", "", environment_line(result.environment), "",
             "#### Time per frame, floor, peak memory, ratios", "", to_markdown(shown)]
    if not result.ratios.empty:
        parts += ["#### Ratios round by round (filter ms / other ms in the same round)", "",
                  to_markdown(result.ratios)]
    scaling = scaling_table(table)
    if not scaling.empty and len(scaling.columns) > 2:
        parts += ["#### Median milliseconds by resolution and threads", "", to_markdown(scaling)]
    if not result.stages.empty:
        parts += ["#### Per-stage milliseconds", "", to_markdown(stage_lines(result.stages))]
    return "\n".join(parts)


__all__ = ["bench_markdown", "environment_line", "scaling_table", "stage_lines"]
