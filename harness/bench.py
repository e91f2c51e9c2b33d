"""``denoise-bench bench``: per-frame filter time against peers and floors, threads, memory.

Each resolution gets one rendered frame (two for temporal filters: the second is timed, with
history) from the render store; every filter, the peers included, runs the timing protocol
(:func:`harness.timer.time_frame`, as in a job) on that same frame, in the same worker
(``local`` executor) or in this process (``inline``), at each requested thread count
(:mod:`harness.threads`: Numba's, OpenCV's and PyTorch's pools, and what plugins read from
:func:`harness.compute_threads`). In the same task, at the same thread count and with the
same protocol, the filter's floor (:mod:`harness.floor`: a kernel that only reads every input
the filter declares and writes one frame) is timed, and the filter's peak memory over one
fresh run of the frames is measured (:mod:`harness.memory`).

The table (:data:`COLUMNS`, one row per filter, resolution and thread count) shows
median/min/max milliseconds, the median process CPU time per call (``cpu_ms``, all threads),
the compile/warm-up call, the floor and ``x_of_floor`` (filter ms / floor ms; ``_cpu``: in CPU
time), peak memory in MB and in float32 RGB frames, RMSE against the reference, each
filter's time relative to every peer at the same resolution and threads (``x_vs_PEER`` = peer
ms / filter ms: above 1 means faster than the peer), to itself at the first resolution
(``x_of_WxH`` = ms / ms at that resolution) and to itself at the first thread count
(``speedup_vs_Nt`` = ms at N threads / ms).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import pandas as pd

from harness.cache import array_hash, make_key
from harness.errors import filter_error, short_error
from harness.executors.base import Executor, Shared, WorkerContext, WorkUnit
from harness.floor import floor_of
from harness.jobs import GroupInputs, emitter_mask
from harness.memory import peak_memory
from harness.plan import Job, choose_renderer, filter_params
from harness.renders import RenderStore
from harness.threads import using_threads
from harness.timer import time_frame

DEFAULT_PEERS = ("opencv_jbf", "oidn")

#: the table's fixed columns and their dtypes (``rmse`` where scored; ratio columns follow)
COLUMNS = {
    "filter": "str", "resolution": "str", "threads": "int64", "ms_median": "float64", "ms_min": "float64",
    "ms_max": "float64", "cpu_ms": "float64", "compile_ms": "float64", "floor_ms": "float64",
    "floor_cpu_ms": "float64", "x_of_floor": "float64", "x_of_floor_cpu": "float64",
    "peak_mb": "float64", "peak_frames": "float64", "traced_mb": "float64", "rss_mb": "float64",
    "rmse": "float64", "status": "str", "notes": "str",
}
MB = 1e6


@dataclass
class BenchResult:
    """The timing table, the per-stage breakdowns and where they were measured.

    Attributes
    ----------
    table : DataFrame
        One row per filter, resolution and thread count (:data:`COLUMNS`, then ratio columns).
    stages : DataFrame
        Per-stage milliseconds of the last timed call of filters that declare ``stage_timing``.
    environment : dict
        :func:`bench_environment` at the start, with ``load_end`` (load average at the end).
    ratios : DataFrame
        With ``--rounds`` (:func:`harness.bench_rounds.bench_rounds`): ratios taken round by
        round (:data:`harness.bench_rounds.RATIO_COLUMNS`); empty otherwise.
    order : dict
        With ``--rounds``: resolution -> each round's call order (entry labels).
    """

    table: pd.DataFrame
    stages: pd.DataFrame
    environment: dict = field(default_factory=dict)
    ratios: pd.DataFrame = field(default_factory=pd.DataFrame)
    order: dict = field(default_factory=dict)


@dataclass
class BenchMeasure:
    """What a :class:`BenchUnit` sends back.

    Attributes
    ----------
    threads : int
        ``numba.get_num_threads()`` in the task, where it ran.
    status : str
        ``ok`` or ``error: ...``.
    timing : dict
        The timing protocol's result on the last frame, with ``compile_ms`` of the first.
    rmse : float
        Against the reference (NaN when not scored).
    floor : dict
        The timing protocol's result for the floor.
    memory : tuple or None
        (traced bytes, RSS bytes) of :func:`filter_memory`.
    notes : list of str
    """

    threads: int
    status: str = "ok"
    timing: dict = field(default_factory=dict)
    rmse: float = math.nan
    floor: dict = field(default_factory=dict)
    memory: tuple | None = None
    notes: list = field(default_factory=list)


@dataclass
class BenchUnit(WorkUnit):
    """One filter at one resolution and thread count: its time, its floor's, its peak memory.

    The filter runs the timing protocol (:func:`harness.timer.time_frame`) on each frame of the
    shared inputs, as a job does (:func:`harness.jobs.run_job`), showing it only its declared
    channels; its last output is scored with ``rmse`` where asked (emitter pixels left out, as in
    a job).

    Attributes
    ----------
    job : Job
        The filter, its parameters, backend, resolution and repeats.
    shared : Shared
        The resolution's :class:`harness.jobs.GroupInputs`.
    threads : int or None
        Threads for every pool while the task runs (None: as the worker is).
    score : bool
        Score ``rmse`` against the last frame's reference.
    """

    job: Job
    shared: Shared
    threads: int | None = None
    score: bool = False
    timed = True

    @property
    def label(self) -> str:
        j = self.job
        threads = "" if self.threads is None else f", {self.threads} thread(s)"
        return f"{j.filter}/{j.backend} at {j.width}x{j.height}{threads}"

    def run(self, context: WorkerContext, shared: GroupInputs) -> BenchMeasure:
        job = self.job
        with using_threads(self.threads) as count:
            measure = BenchMeasure(threads=count)
            spec = context.registry.get("filter", job.filter)
            frames = [f.subset((spec.requires | spec.optional) & f.channels) for f in shared.frames]
            try:
                filt = spec.factory(backend=job.backend, **job.param_dict)
                filt.reset()
                for t, frame in enumerate(frames):  # the frames before the last: one call each
                    repeats = job.repeats if t == len(frames) - 1 else 1
                    filt, out, timing, _ = time_frame(filt, spec, job.backend, frame, t == 0, repeats,
                                                      check=f"filter {job.filter!r}")
                    measure.timing.setdefault("compile_ms", timing.get("compile_ms", math.nan))
                    context.progress(1)
            except (Exception, SystemExit) as exc:
                measure.status = f"error: {filter_error(exc)}"
                return measure
            measure.timing.update({k: v for k, v in timing.items() if k != "compile_ms"})
            if self.score:
                measure.rmse = output_rmse(context.registry, out, shared, job)
            if job.backend == "cpu":
                try:
                    measure.floor = time_floor(spec, frames, job.repeats)
                except Exception as exc:
                    measure.notes.append(f"floor failed: {short_error(exc, 120)}")
            else:
                measure.notes.append("no floor: it is a CPU kernel")
            try:
                peak = filter_memory(spec, job, frames)
                measure.memory = (peak.traced, peak.rss)
            except (Exception, SystemExit) as exc:
                measure.notes.append(f"memory not measured: {short_error(exc, 120)}")
        return measure


def output_rmse(registry, out, inputs: GroupInputs, job: Job) -> float:
    """``rmse`` of ``out`` against the last frame's reference, emitters left out as in a job."""
    mspec = registry.get("metric", "rmse")
    extra = {}
    if "mask" in mspec.accepts:
        extra["mask"] = emitter_mask(inputs.frames[-1]) if job.emitters == "exclude" else None
    if "reference_variance" in mspec.accepts:
        extra["reference_variance"] = None
    return float(mspec.factory()(out, inputs.references[-1], **extra))


def time_floor(spec, frames: Sequence, repeats: int) -> dict:
    """The timing protocol applied to the floor of ``spec`` on ``frames`` (its last frame's timing).

    ``frames`` are what the filter sees (its declared channels); the last frame is timed with
    ``repeats`` calls, the ones before it with one, as :class:`BenchUnit` does for the filter,
    each frame after a warm-up call (on a copy: the state goes on from the timed calls): a temporal floor also
    reads its history from the second frame on, a new input layout and so a new kernel to
    compile, which a timed call must not include.
    """
    floor, fspec = floor_of(spec)
    floor.reset()
    timing: dict = {}
    for k, frame in enumerate(frames):
        # not validated: its output is a sum, infinite where an input is (depth of the background)
        floor, _, timing, _ = time_frame(floor, fspec, "cpu", frame, True, repeats if k == len(frames) - 1 else 1)
    return timing


def filter_memory(spec, job: Job, frames: Sequence):
    """Peak memory (:class:`harness.memory.MemoryPeak`) of a fresh filter run over ``frames``.

    The filter is built, reset and called on every frame (a temporal filter builds its
    history) inside the measurement, so the peak covers its state, its scratch, its
    temporaries and its output. Its kernels are compiled by then (the task timed it first).
    """
    def work():
        filt = spec.factory(backend=job.backend, **job.param_dict)
        filt.reset()
        out = None
        for frame in frames:
            out = filt(frame, sampler=None)
        return out

    return peak_memory(work)[1]


def bench_environment() -> dict:
    """Where a bench runs: CPU model, cores, Numba's thread limit, load average, library versions."""
    from harness.machine import cpu_model
    from harness.manifest import package_versions
    from harness.threads import max_threads

    keep = ("numpy", "numba", "llvmlite", "opencv-contrib-python-headless", "pyoidn", "torch")
    versions = package_versions()
    return {
        "cpu": cpu_model(), "cores": os.cpu_count(), "max_threads": max_threads(),
        "load_start": load_average(), "python": sys.version.split()[0],
        "versions": {k: versions.get(k) for k in keep if versions.get(k)},
        "date": time.strftime("%Y-%m-%d %H:%M %Z"),
    }


def load_average() -> float:
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:
        return math.nan


def bench_filters(
    registry,
    store: RenderStore,
    executor: Executor,
    filters: Sequence[str],
    *,
    peers: Sequence[str] = (),
    scene: str = "synthetic-edges",
    renderer: str | None = None,
    task: str = "denoise",
    resolutions: Sequence[tuple[int, int]] = ((1280, 720),),
    threads: Sequence[int | None] = (None,),
    backend: str = "cpu",
    repeats: int = 10,
    steady: int = 0,
    params: Mapping[str, Mapping] | None = None,
    presets: Mapping[str, str] | None = None,
    error: bool = True,
    progress: Callable[[str], None] | None = None,
) -> BenchResult:
    """Time ``filters`` and ``peers`` on the same frame at each resolution and thread count.

    Parameters
    ----------
    registry : harness.Registry
    store : RenderStore
        Renders the frames (its resolution override is ignored: ``resolutions`` rule).
    executor : Executor
        Where the timing runs.
    filters, peers : sequence of str
    scene : str
        A registered scene.
    renderer : str, optional
        Default: the scene's preferred renderer for ``task``.
    task : str
    resolutions : sequence of (width, height)
    threads : sequence of int or None
        Thread counts to time at, each in [1, :func:`harness.threads.max_threads`] of the
        worker (None: the worker's own count, all cores unless ``NUMBA_NUM_THREADS`` says less).
    backend : str
    repeats : int
        Timed calls of the last frame (>= 1).
    steady : int
        Frames run (one call each) before the timed one: a temporal filter's steady state
        (0: one frame, two where a filter is temporal).
    params, presets : mappings, optional
        As for :func:`harness.plan.make_plan`.
    error : bool
        Score each output's ``rmse`` against the renderer's reference (default). False skips
        the reference: the raster renderer's 8 x 8 SSAA reference is drawn whole, about 6 GB
        at 1280x720 and 13 GB at 1920x1080.
    progress : callable, optional
        Receives one line per finished (filter, resolution, threads).

    Returns
    -------
    BenchResult
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats must be an integer >= 1, got {repeats!r}")
    threads = thread_list(threads)
    environment = bench_environment()
    setup = BenchSetup.of(registry, filters, peers, scene=scene, renderer=renderer, task=task, params=params,
                          presets=presets, steady=steady, error=error)
    peers, specs, rname, rspec = setup.peers, setup.specs, setup.renderer, setup.rspec
    configured, frames, metric, channels = setup.configured, setup.frames, setup.metric, setup.channels
    say = progress or (lambda line: None)
    rows, stages = [], []
    for width, height in resolutions:
        sized = RenderStore(registry, store.cache, resolution=(width, height))
        inputs = bench_inputs(sized, scene, rname, rspec, frames, channels, with_reference=metric is not None)
        shared = Shared(make_key(bench=[scene, rname, width, height, frames]), inputs)
        tasks = []
        for count in threads:
            for spec in specs:
                fparams, preset = configured[spec.name]
                job = Job(task, scene, rname, spec.name, setup.backend_of(spec, backend),
                          json.dumps(fparams, sort_keys=True, default=str), preset, 1, 0, width=width, height=height,
                          frames=frames, repeats=repeats)
                tasks.append(BenchUnit(job, shared, count, score=metric is not None))
        for index, outcome in executor.run(tasks):
            bench_task = tasks[index]
            row, stage = _table_row(bench_task, outcome, width * height, metric)
            note = backend_note(bench_task.job.backend, backend)
            if note:
                row["notes"] = "; ".join(n for n in (row.get("notes", ""), note) if n)
            rows.append(row)
            if stage:
                stages.append(stage)
            say(f"{row['filter']} at {row['resolution']}, {row['threads']} thread(s): "
                + (f"{row['ms_median']:.4g} ms, floor {row['floor_ms']:.4g} ms" if row["status"] == "ok"
                   else row["status"]))
    table = typed_table(pd.DataFrame(rows), with_rmse=metric is not None)
    add_ratios(table, peers, resolutions, threads)
    environment["load_end"] = load_average()
    return BenchResult(table, pd.DataFrame(stages), environment)


def thread_list(threads) -> list:
    """The distinct thread counts in order (``[None]``: the harness's default), each checked."""
    threads = list(dict.fromkeys(threads)) or [None]
    for n in threads:
        if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 1):
            raise ValueError(f"thread counts must be integers >= 1 (or None), got {n!r}")
    return threads


@dataclass
class BenchSetup:
    """What a bench times, resolved from its settings (shared by :func:`bench_filters` and
    :func:`harness.bench_rounds.bench_rounds`).

    Attributes
    ----------
    names : list of str
        The filters, then the peers that are not among them.
    peers : list of str
    specs : list of FilterSpec
        Of ``names``.
    renderer : str
    rspec : RendererSpec
    configured : dict
        ``name -> (params, preset)`` of each filter (:func:`harness.plan.filter_params`).
    frames : int
        Frames per call sequence (:func:`sequence_frames`).
    metric : str or None
        ``rmse`` where the error is scored (the renderer makes references), else None.
    channels : frozenset
        Every channel any of the filters reads that the renderer provides.
    """

    names: list
    peers: list
    specs: list
    renderer: str
    rspec: object
    configured: dict
    frames: int
    metric: str | None
    channels: frozenset

    @classmethod
    def of(cls, registry, filters: Sequence[str], peers: Sequence[str], *, scene: str, renderer: str | None,
           task: str, params: Mapping | None, presets: Mapping | None, steady: int, error: bool) -> BenchSetup:
        peers = [p for p in peers if p not in filters]
        names = list(dict.fromkeys([*filters, *peers]))
        specs = [registry.get("filter", n) for n in names]
        rname = renderer or choose_renderer(registry, registry.get("scene", scene), task)
        if rname is None:
            raise ValueError(f"no renderer serves task {task!r} for scene {scene!r}")
        rspec = registry.get("renderer", rname)
        configured = {s.name: filter_params(s, (presets or {}).get(s.name), (params or {}).get(s.name, {}))
                      for s in specs}
        metric = "rmse" if error and "rmse" in registry.metrics and rspec.references else None
        channels = frozenset().union(*[(s.requires | s.optional) & rspec.provides for s in specs])
        return cls(names, peers, specs, rname, rspec, configured, sequence_frames(registry, scene, specs, steady),
                   metric, channels)

    def backend_of(self, spec, backend: str) -> str:
        """The backend ``spec`` is timed on: ``backend``, or a peer's first own backend where it lacks
        that one (``--backend cuda`` with CPU-only peers times the peers on the CPU, and says so)."""
        if spec.name in self.peers and backend not in spec.backends:
            return spec.backends[0]
        return backend


def backend_note(job_backend: str, backend: str) -> str:
    """The note of a row timed on another backend than the bench's (empty when the same)."""
    return "" if job_backend == backend else f"timed on {job_backend}: no {backend} backend"


def sequence_frames(registry, scene: str, specs: Sequence, steady: int) -> int:
    """Frames a bench renders: ``steady`` + 1 where asked, else 2 where a filter is temporal, else 1.

    Raises
    ------
    ValueError
        For ``steady`` < 0 or more frames than a sequence scene has.
    """
    if isinstance(steady, bool) or not isinstance(steady, int) or steady < 0:
        raise ValueError(f"--steady must be an integer >= 1, got {steady!r}")
    if not steady:
        return 2 if any(s.temporal for s in specs) else 1
    count = getattr(registry.get("scene", scene), "frames", None)
    if isinstance(count, int) and 1 < count < steady + 1:  # a still scene renders any frame index
        raise ValueError(f"--steady {steady}: scene {scene!r} has {count} frame(s); at most --steady {count - 1}")
    return steady + 1


def _table_row(bench_task: BenchUnit, outcome, pixels: int, metric: str | None) -> tuple[dict, dict | None]:
    """The table row of one task's outcome and its per-stage row (None without stage timing)."""
    job = bench_task.job
    res = f"{job.width}x{job.height}"
    measure = outcome.value if outcome.ok else None
    threads = measure.threads if measure is not None else (bench_task.threads or -1)
    base = {"filter": job.filter, "resolution": res, "threads": threads}
    if measure is None or measure.status != "ok":
        return {**base, "status": outcome.error if measure is None else measure.status}, None
    timing, floor = measure.timing, measure.floor
    floor_ms, floor_cpu = floor.get("ms_median", math.nan), floor.get("cpu_ms_median", math.nan)
    row = timing_row(base, ms=(timing["ms_median"], timing["ms_min"], timing["ms_max"]),
                     cpu_ms=timing["cpu_ms_median"], compile_ms=timing["compile_ms"], floor=(floor_ms, floor_cpu),
                     x_of_floor=(_ratio(timing["ms_median"], floor_ms), _ratio(timing["cpu_ms_median"], floor_cpu)),
                     memory=measure.memory, pixels=pixels, notes=measure.notes)
    if metric:
        row["rmse"] = measure.rmse
    return row, stage_row(base, timing.get("stage_ms"))


def timing_row(base: dict, *, ms, cpu_ms: float, compile_ms: float, floor, x_of_floor, memory, pixels: int,
               notes) -> dict:
    """A table row of a timed filter (the columns of :data:`COLUMNS` but ``rmse``).

    Parameters
    ----------
    base : dict
        ``filter``, ``resolution`` and ``threads``.
    ms : (float, float, float)
        Median, minimum and maximum wall milliseconds per call.
    cpu_ms, compile_ms : float
    floor, x_of_floor : (float, float)
        The floor's wall and CPU milliseconds, and the filter's ratios to them.
    memory : (float, float) or None
        Traced and resident peak bytes (NaN: not measured).
    pixels : int
    notes : sequence of str
    """
    traced, rss = memory if memory is not None else (math.nan, math.nan)
    peak = max(traced, rss) if not math.isnan(rss) else traced
    return {**base, "ms_median": ms[0], "ms_min": ms[1], "ms_max": ms[2], "cpu_ms": cpu_ms, "compile_ms": compile_ms,
            "floor_ms": floor[0], "floor_cpu_ms": floor[1], "x_of_floor": x_of_floor[0],
            "x_of_floor_cpu": x_of_floor[1], "peak_mb": peak / MB, "peak_frames": peak / (pixels * 3 * 4),
            "traced_mb": traced / MB, "rss_mb": rss / MB, "status": "ok", "notes": "; ".join(notes)}


def stage_row(base: dict, stage_ms: str | None) -> dict | None:
    """The per-stage row of a call's ``stage_ms`` JSON (None without one); a stage named like a key
    column (sbf's "filter") gets " (stage)"."""
    if not stage_ms:
        return None
    stages = json.loads(stage_ms)
    return {**base, **{(f"{k} (stage)" if k in base else k): v for k, v in stages.items()}}


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else math.nan


def typed_table(table: pd.DataFrame, with_rmse: bool, extra: Sequence[str] = ()) -> pd.DataFrame:
    """The fixed columns in :data:`COLUMNS` order and dtypes (missing values: NaN, ""), then the
    ``extra`` numeric ones (float64)."""
    columns = {k: v for k, v in COLUMNS.items() if with_rmse or k != "rmse"}
    columns.update({k: "float64" for k in extra})
    for name, dtype in columns.items():
        if name not in table:
            table[name] = "" if dtype == "str" else math.nan
        if dtype == "str":
            table[name] = table[name].astype(object).where(table[name].notna(), "").astype(str)
        else:
            table[name] = table[name].astype(dtype)
    return table[list(columns)].reset_index(drop=True)


def add_ratios(table: pd.DataFrame, peers, resolutions, threads) -> None:
    """``x_vs_PEER``, ``x_of_WxH`` (first resolution) and ``speedup_vs_Nt`` (first thread count)."""
    if table.empty:
        return
    ms = table.set_index(["filter", "resolution", "threads"])["ms_median"]
    ms = ms[~ms.index.duplicated()]

    def lookup(key) -> float:
        return float(ms.get(key, math.nan))

    keys = list(zip(table["filter"], table["resolution"], table["threads"]))
    own = table["ms_median"].to_numpy()
    ratio = _ratio
    for peer in peers:
        table[f"x_vs_{peer}"] = [ratio(lookup((peer, r, n)), m) for (_, r, n), m in zip(keys, own)]
    if len(resolutions) > 1:
        first = f"{resolutions[0][0]}x{resolutions[0][1]}"
        table[f"x_of_{first}"] = [ratio(m, lookup((f, first, n))) for (f, _, n), m in zip(keys, own)]
    counts = [n for n in threads if n is not None]
    if len(counts) > 1:
        table[f"speedup_vs_{counts[0]}t"] = [ratio(lookup((f, r, counts[0])), m) for (f, r, _), m in zip(keys, own)]


def bench_inputs(store: RenderStore, scene: str, renderer: str, rspec, frames: int, channels,
            with_reference: bool) -> GroupInputs:
    inputs = GroupInputs([], [], [], [], channels=channels)
    for t in range(frames):
        inputs.frames.append(store.frame(scene, renderer, t, spp=1, seed=0, channels=channels))
        ref = store.reference(scene, renderer, t, spp=rspec.reference_spp) if with_reference else None
        inputs.references.append(ref)
        inputs.reference_hashes.append(array_hash(ref) if ref is not None else "")
        inputs.repaired.append(0)
    return inputs
