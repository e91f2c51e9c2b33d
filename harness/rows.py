"""The result row: one definition from which the table's column order and dtypes derive.

A results table has one row per (job, frame). :class:`Row` lists the fixed columns in order;
the metric columns (one float column per metric, NaN where not scored) sit between the
identifying columns (``part="head"``) and the measurement columns (``part="tail"``). Adding a
column is one field here.

========================  ==============================================================
``job_id``                digest of every input of the job (see :class:`harness.plan.Job`)
``task``                  ``denoise`` or ``antialias``
``scene``, ``scene_hash`` scene name and content hash
``tier``                  the scene's tier: ``procedural`` (built here) or ``real`` (third-party content);
                          leaderboards rank each tier on its own
``renderer``              renderer name
``filter``, ``preset``    filter name and named preset ("" for defaults)
``params``                JSON of the filter parameters actually used
``backend``               ``cpu`` or ``cuda``
``guides``                the guide channels the filter had (comma-separated; ``motion(camera)``: motion
                          it derived from the camera, :func:`harness.camera_motion`), then ``; without X``
                          naming those of its full algorithm that were missing (a degraded mode,
                          :attr:`harness.FilterSpec.full_guides`); "" where it never ran
``spp``, ``seed``         nominal samples per pixel and seed of the render
``frame``                 frame index (-1 on the row of a job that never reached a frame)
``width``, ``height``     resolution in pixels
``status``                ``ok``, ``skipped`` or ``error``
``message``               why skipped, or a short error message
``notes``                 metrics skipped and why; non-finite input repaired
<metric>                  one float column per metric; sequence metrics on the job's last frame
<metric>_per_frame        a sequence metric declaring ``per_frame`` (``temporal_error``) scored on
                          frames (t - 1, t), on frame t's row (NaN on frame 0): a time series
``samples_used``          samples rendered for this frame, adaptive extras included
``compile_ms``            the first call on a new shape (compile/warm-up), first frame only
``ms_median/min/max``     per-frame filter time over ``repeats`` calls
``repeats``               timed calls per frame
``stage_ms``              JSON of the filter's own per-stage breakdown, if it declares one
``ms_1280x720``           median per-frame filter time on a 1280x720 frame of the timing scene
``ms_1920x1080``          the same at 1920x1080 (both on the rows of one job per filter configuration,
                          task and spp, see :mod:`harness.real_resolutions`; NaN on the others)
``threads``               Numba threads of the process that ran the job
``machine``               CPU (and GPU) of the machine that ran the job
``nonfinite_repaired``    values replaced under ``--nonfinite repair``
``reference_spp``         samples per pixel of this frame's reference (0: analytic)
``reference_hash``        SHA-256 of this frame's reference image
``reference_error``       its median relative standard error (:mod:`harness.references`; NaN unknown)
``reference_noise``       its RMS standard error over the scored pixels, linear radiance: the RMSE a
                          perfect output would show uncorrected; ``rmse`` differences below it are
                          not resolved by this reference
``reference_noise_display`` the same on the displayed image (``display_rmse``'s floor)
========================  ==============================================================

Timing columns (``timing=True``) and ``machine``/``threads`` are the only ones that differ
between two runs of the same inputs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import pandas as pd

_DEFAULTS = {"str": "", "int64": -1, "float64": math.nan}


def _col(dtype: str, part: str = "head", timing: bool = False):
    return field(default=_DEFAULTS[dtype], metadata={"dtype": dtype, "part": part, "timing": timing})


@dataclass
class Row:
    """One row of a results table (see the module docstring for each column)."""

    job_id: str = _col("str")
    task: str = _col("str")
    scene: str = _col("str")
    scene_hash: str = _col("str")
    tier: str = _col("str")
    renderer: str = _col("str")
    filter: str = _col("str")
    preset: str = _col("str")
    params: str = _col("str")
    backend: str = _col("str")
    guides: str = _col("str")
    spp: int = _col("int64")
    seed: int = _col("int64")
    frame: int = _col("int64")
    width: int = _col("int64")
    height: int = _col("int64")
    status: str = _col("str")
    message: str = _col("str")
    notes: str = _col("str")
    samples_used: int = _col("int64", "tail")
    compile_ms: float = _col("float64", "tail", timing=True)
    ms_median: float = _col("float64", "tail", timing=True)
    ms_min: float = _col("float64", "tail", timing=True)
    ms_max: float = _col("float64", "tail", timing=True)
    repeats: int = _col("int64", "tail", timing=True)
    stage_ms: str = _col("str", "tail", timing=True)
    ms_1280x720: float = _col("float64", "tail", timing=True)
    ms_1920x1080: float = _col("float64", "tail", timing=True)
    threads: int = _col("int64", "tail")
    machine: str = _col("str", "tail")
    nonfinite_repaired: int = _col("int64", "tail")
    reference_spp: int = _col("int64", "tail")
    reference_hash: str = _col("str", "tail")
    reference_error: float = _col("float64", "tail")
    reference_noise: float = _col("float64", "tail")
    reference_noise_display: float = _col("float64", "tail")
    metrics: dict = field(default_factory=dict, metadata={"part": "metrics"})

    def as_dict(self) -> dict:
        """The row as a flat mapping: the fixed columns and one entry per metric."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "metrics"}
        out.update(self.metrics)
        return out


def _columns(part: str) -> list[str]:
    return [f.name for f in fields(Row) if f.metadata.get("part") == part]


#: identifying columns, before the metrics
HEAD_COLUMNS: list[str] = _columns("head")
#: measurement columns, after the metrics
TAIL_COLUMNS: list[str] = _columns("tail")
#: columns that hold times (differ between runs of the same inputs)
TIMING_COLUMNS: list[str] = [f.name for f in fields(Row) if f.metadata.get("timing")]
#: dtype of every fixed column
DTYPES: dict[str, str] = {f.name: f.metadata["dtype"] for f in fields(Row) if "dtype" in f.metadata}
#: the order rows are sorted in
SORT_KEYS = ["task", "scene", "renderer", "filter", "backend", "preset", "params", "spp", "seed", "frame"]


#: the real resolutions filters are timed at, each with its column ``ms_<w>x<h>``
REAL_RESOLUTIONS = ((1280, 720), (1920, 1080))


def timing_column(width: int, height: int) -> str:
    """The column of the per-frame time at a real resolution (one of :data:`REAL_RESOLUTIONS`)."""
    if (width, height) not in REAL_RESOLUTIONS:
        raise ValueError(f"filters are timed at {[f'{w}x{h}' for w, h in REAL_RESOLUTIONS]}, not {width}x{height}")
    return f"ms_{width}x{height}"


#: suffix of the column holding a ``per_frame`` sequence metric's value on each frame
PER_FRAME_SUFFIX = "_per_frame"


def per_frame_column(metric: str) -> str:
    """The column of a ``per_frame`` sequence metric's values on each frame (``<metric>_per_frame``)."""
    return metric + PER_FRAME_SUFFIX


def metric_columns(df: pd.DataFrame) -> list[str]:
    """The metric columns of a results table (every column that is not a fixed one)."""
    return [c for c in df.columns if c not in DTYPES]


def make_table(rows, metric_names=()) -> pd.DataFrame:
    """A DataFrame in the documented column order and dtypes.

    Parameters
    ----------
    rows : iterable of Row or dict
    metric_names : iterable of str
        Metric columns to include even where no row has a value.
    """
    records = [r.as_dict() if isinstance(r, Row) else dict(r) for r in rows]
    metrics = list(dict.fromkeys([*metric_names, *(k for r in records for k in r if k not in DTYPES)]))
    df = pd.DataFrame(records, columns=HEAD_COLUMNS + metrics + TAIL_COLUMNS)
    return conform(df, metrics)


def conform(df: pd.DataFrame, metrics=None) -> pd.DataFrame:
    """``df`` with every fixed column present in order, metrics in between, dtypes as declared."""
    metrics = sorted(metric_columns(df)) if metrics is None else list(metrics)
    df = df.reindex(columns=HEAD_COLUMNS + metrics + TAIL_COLUMNS)
    for name, dtype in DTYPES.items():
        if dtype == "str":
            df[name] = df[name].astype(object).where(df[name].notna(), "").astype(str)
        elif dtype == "int64":
            df[name] = pd.to_numeric(df[name], errors="coerce").fillna(-1).astype("int64")
        else:
            df[name] = pd.to_numeric(df[name], errors="coerce").astype("float64")
    for name in metrics:
        df[name] = pd.to_numeric(df[name], errors="coerce").astype("float64")
    return df


def combine(tables) -> pd.DataFrame:
    """Concatenate tables (metric columns united, sorted by name) in the documented order."""
    tables = [t for t in tables if len(t)]
    if not tables:
        return make_table([])
    df = pd.concat(tables, ignore_index=True, sort=False)
    df = conform(df)
    return df.sort_values(SORT_KEYS, kind="stable").reset_index(drop=True)
