"""The stress results table: one row per (filter, backend, case), and the filter x case matrix.

Columns (in order):

================  ==================================================================
``filter``        filter name
``backend``       ``cpu`` or ``cuda``
``params``        JSON of the parameters the filter was built with
``case``          battery case, ``fuzz`` (a fuzzing search) or ``replay:<file>``
``group``         the case's group (``colour``, ``guide``, ``shape``, ``sequence``, ``policy``,
                  ``fuzz``, ``replay``)
``status``        what happened: ``pass``,
                  ``rejected`` (a clear ``ValueError`` on invalid input), ``nonfinite``,
                  ``out_of_bounds``, ``mean_shift``, ``unstable``, ``reset_differs``, ``memory``,
                  ``error``, ``crash``, ``timeout``, ``skipped``
``verdict``       what it means: ``pass``, ``fail``, ``declared`` (a failure the filter declares
                  in ``stress_exempt``), ``stale`` (declared, but passes), ``n/a`` (skipped)
``message``       what failed, one line (or why the case does not apply)
``exempt``        the reason the filter declares for this case ("" if none)
``notes``         extra measurements (energy of long sequences, fuzzing statistics)
``frame``         frame where it failed (-1: none)
``calls``         filter calls made
``height``, ``width``  size of the first frame
``ms_median``, ``ms_max``  per-call filter time, milliseconds (compilation excluded: the worker
                  warms each filter up first)
``peak_mb``       the largest growth of the worker's resident memory during one filter call, MiB
``reproducer``    the saved ``.npz`` of a fuzzing failure ("" if none)
``command``       the command line that runs this case again (``--replay FILE`` for fuzzing)
``machine``, ``threads``  where it ran
================  ==================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import pandas as pd

from harness.stress.properties import PASSING


@dataclass
class StressRow:
    """One row of a stress table (see the module docstring)."""

    filter: str = ""
    backend: str = ""
    params: str = ""
    case: str = ""
    group: str = ""
    status: str = ""
    verdict: str = ""
    message: str = ""
    exempt: str = ""
    notes: str = ""
    frame: int = -1
    calls: int = 0
    height: int = -1
    width: int = -1
    ms_median: float = math.nan
    ms_max: float = math.nan
    peak_mb: float = math.nan
    reproducer: str = ""
    command: str = ""
    machine: str = ""
    threads: int = -1


COLUMNS = [f.name for f in fields(StressRow)]


def verdict(status: str, exempt: str) -> str:
    """``pass``, ``fail``, ``declared``, ``stale`` or ``n/a`` for a status and the declared exemption."""
    if status == "skipped":
        return "n/a"
    if status in PASSING:
        return "stale" if exempt else "pass"
    return "declared" if exempt else "fail"


def make_table(rows) -> pd.DataFrame:
    """A DataFrame of :class:`StressRow` (or dicts) in column order."""
    records = [vars(r) if isinstance(r, StressRow) else dict(r) for r in rows]
    df = pd.DataFrame(records, columns=COLUMNS)
    for f in fields(StressRow):
        if f.type == "str":
            df[f.name] = df[f.name].fillna("").astype(str)
        elif f.type == "int":
            df[f.name] = pd.to_numeric(df[f.name]).fillna(-1).astype("int64")
        else:
            df[f.name] = pd.to_numeric(df[f.name]).astype("float64")
    return df


#: how each status reads in the matrix
LABELS = {
    "pass": "ok", "rejected": "rejects", "nonfinite": "NaN/Inf", "out_of_bounds": "bounds", "mean_shift": "mean",
    "unstable": "energy", "reset_differs": "reset", "memory": "memory", "error": "error", "crash": "CRASH",
    "timeout": "timeout", "skipped": "-",
}


def cell(row) -> str:
    """The matrix cell of a row: the status, the median ms of a passing case, ``(declared)`` for exemptions."""
    text = LABELS.get(row.status, row.status)
    if row.status in PASSING and not math.isnan(row.ms_median):
        text += f" {row.ms_median:.3g}"
    if row.verdict == "declared":
        text += " (declared)"
    elif row.verdict == "stale":
        text += " (declared, passes)"
    return text


def matrix(df: pd.DataFrame) -> pd.DataFrame:
    """Cases down, ``filter/backend`` across (or ``filter`` where every row is on one backend)."""
    if df.empty:
        return pd.DataFrame()
    one_backend = df["backend"].nunique() == 1
    entries = df["filter"] if one_backend else df["filter"] + "/" + df["backend"]
    shown = df.assign(entry=entries, cell=[cell(r) for r in df.itertuples()])
    order = list(dict.fromkeys(shown.case))
    table = shown.pivot_table(index="case", columns="entry", values="cell", aggfunc="first", sort=False)
    table = table.reindex(index=order, columns=sorted(set(entries))).fillna("")
    table.columns.name = None
    return table.reset_index()


def failures(df: pd.DataFrame) -> pd.DataFrame:
    """Rows whose verdict is not ``pass``/``n/a``: filter, backend, case, verdict, status, message, command."""
    bad = df[~df.verdict.isin(["pass", "n/a"])]
    return bad[["filter", "backend", "case", "verdict", "status", "frame", "message", "exempt", "reproducer",
                "command"]]


def per_filter(df: pd.DataFrame) -> pd.DataFrame:
    """Cases of each verdict per ``filter/backend`` (columns in the order pass, declared, stale, fail, n/a)."""
    table = pd.crosstab(df["filter"] + "/" + df["backend"], df["verdict"])
    table = table.reindex(columns=[v for v in ("pass", "declared", "stale", "fail", "n/a") if v in table.columns])
    table.index.name, table.columns.name = "filter", None
    return table.reset_index()


def counts(df: pd.DataFrame) -> dict:
    """How many rows have each verdict."""
    return {k: int(v) for k, v in df.verdict.value_counts().items()}
