"""The results schema, pandas tables, the leaderboard and the run manifest.

One row per (job, frame). Columns, in order:

========================  ==============================================================
``job_id``                digest of the job's identifiers (stable across runs)
``scene``, ``scene_hash`` scene name and content hash
``renderer``              renderer name
``filter``, ``preset``    filter name and named preset ("" for defaults)
``params``                JSON of the filter parameters actually used
``backend``               ``cpu`` or ``cuda``
``spp``, ``seed``         nominal samples per pixel and seed of the render
``frame``                 frame index (-1 on the row of a job that never reached a frame)
``width``, ``height``     resolution in pixels
``status``                ``ok``, ``skipped`` or ``error``
``message``               why skipped, or a short error message
``notes``                 metrics skipped and why; non-finite input repaired
<metric>                  one float column per metric (NaN where not scored); sequence
                          metrics are reported on the row of the job's last frame
``samples_used``          samples rendered for this frame, adaptive extras included
``compile_ms``            the first call on a new shape (compile/warm-up), first frame only
``ms_median``, ``ms_min``, ``ms_max``  per-frame filter time over ``repeats`` calls
``repeats``               timed calls per frame
``stage_ms``              JSON of the filter's own per-stage breakdown, if it reports one
``threads``               Numba threads during the run
``nonfinite_repaired``    non-finite input values replaced under ``--nonfinite repair``
========================  ==============================================================

Timing columns are the only ones that differ between two runs with the same inputs.
"""

from __future__ import annotations

import io
import json
import math
import os
import platform
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd

from harness.cache import atomic_write_bytes

ID_COLUMNS = [
    "job_id",
    "scene",
    "scene_hash",
    "renderer",
    "filter",
    "preset",
    "params",
    "backend",
    "spp",
    "seed",
    "frame",
    "width",
    "height",
    "status",
    "message",
    "notes",
]
TIMING_COLUMNS = ["compile_ms", "ms_median", "ms_min", "ms_max", "repeats", "stage_ms"]
TAIL_COLUMNS = ["samples_used", *TIMING_COLUMNS, "threads", "nonfinite_repaired"]
PACKAGES = [
    "numpy",
    "numba",
    "llvmlite",
    "pyvista",
    "vtk",
    "OpenImageIO",
    "scikit-image",
    "pandas",
    "pyarrow",
    "torch",
    "pluggy",
    "flip-evaluator",
    "tqdm",
    "opencv-contrib-python-headless",
    "pyoidn",
]


def make_table(rows: list[dict], metric_names: list[str]) -> pd.DataFrame:
    """A DataFrame with the documented column order and dtypes from result rows."""
    columns = ID_COLUMNS + list(metric_names) + TAIL_COLUMNS
    df = pd.DataFrame(rows, columns=columns)
    for name in metric_names + ["compile_ms", "ms_median", "ms_min", "ms_max"]:
        df[name] = pd.to_numeric(df[name], errors="coerce").astype("float64")
    for name in ["spp", "seed", "frame", "width", "height", "repeats", "threads", "nonfinite_repaired", "samples_used"]:
        df[name] = pd.to_numeric(df[name], errors="coerce").fillna(-1).astype("int64")
    for name in [
        "job_id",
        "scene",
        "scene_hash",
        "renderer",
        "filter",
        "preset",
        "params",
        "backend",
        "status",
        "message",
        "notes",
        "stage_ms",
    ]:
        df[name] = df[name].fillna("").astype(str)
    return df


def metric_columns(df: pd.DataFrame) -> list[str]:
    """The metric columns of a results table."""
    fixed = set(ID_COLUMNS) | set(TAIL_COLUMNS)
    return [c for c in df.columns if c not in fixed]


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
    return pd.read_parquet(path)


def combine(tables: list[pd.DataFrame]) -> pd.DataFrame:
    """Concatenate job tables, keeping the documented column order (metrics in between)."""
    tables = [t for t in tables if len(t)]
    if not tables:
        return make_table([], [])
    df = pd.concat(tables, ignore_index=True, sort=False)
    metrics = sorted({c for t in tables for c in metric_columns(t)})
    df = df.reindex(columns=ID_COLUMNS + metrics + TAIL_COLUMNS)
    return df.sort_values(
        ["scene", "renderer", "filter", "backend", "preset", "spp", "seed", "frame"], kind="stable"
    ).reset_index(drop=True)


def summary(df: pd.DataFrame) -> pd.DataFrame:
    """Per (scene, filter, backend, preset, spp): mean of each metric, median ms, samples, status counts."""
    metrics = metric_columns(df)
    keys = ["scene", "filter", "preset", "backend", "spp"]
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
    """Filters ranked by their mean rank over scenes and metrics (best first).

    Parameters
    ----------
    df : DataFrame
        A results table.
    metric_specs : mapping name -> MetricSpec
        For the direction of each metric (metrics without a spec count as lower-is-better).
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
        ranks.append(summ.groupby("scene")[m].rank(ascending=not higher, method="average"))
    summ["rank"] = pd.concat(ranks, axis=1).mean(axis=1) if ranks else math.nan
    cols = ["entry"] + [m for m in metric_columns(df) if summ[m].notna().any()] + ["ms_median", "rank"]
    board = summ.groupby("entry")[cols[1:]].mean().sort_values("rank").reset_index()
    return board


def _git_commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, check=False)
        commit = out.stdout.strip() if out.returncode == 0 else ""
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        ).stdout.strip()
        return commit + ("+dirty" if dirty and commit else "")
    except (OSError, subprocess.SubprocessError):
        return ""


def machine_info() -> dict:
    """CPU, cores, Numba threads and GPU of this machine."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    gpu = ""
    try:
        from numba import cuda

        if cuda.is_available():
            gpu = (
                cuda.get_current_device().name.decode()
                if isinstance(cuda.get_current_device().name, bytes)
                else str(cuda.get_current_device().name)
            )
    except Exception:
        gpu = ""
    import numba

    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "gpu": gpu,
        "platform": platform.platform(),
    }


def package_versions() -> dict:
    out = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def make_manifest(registry, plan, options: dict, scene_hashes: dict, reference_hashes: dict) -> dict:
    """The run manifest: everything needed to reproduce and audit a run."""
    from harness import __version__

    return {
        "harness_version": __version__,
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]) if sys.argv else "",
        "options": options,
        "git_commit": _git_commit(),
        "machine": machine_info(),
        "python": sys.version.split()[0],
        "packages": package_versions(),
        "plugins": [r.as_dict() for r in registry.records],
        "jobs": len(plan.jobs),
        "skipped_jobs": len(plan.skipped),
        "seeds": sorted({g.seed for g in plan.groups}),
        "scenes": scene_hashes,
        "references": reference_hashes,
    }


def write_manifest(manifest: dict, path: Path) -> None:
    atomic_write_bytes(Path(path), json.dumps(manifest, indent=2, sort_keys=True, default=str).encode())


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
