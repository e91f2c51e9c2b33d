"""``denoise-bench bench --rounds``: the filters timed in turn, call by call, in one process.

Where :mod:`harness.bench` times each filter in a task of its own (``--repeats`` calls in a
row), this times every entry of a resolution in one task (:class:`RoundsTask`): the filters,
their peers, their floors (:mod:`harness.floor`), with ``--baseline REV`` the filters as they
were at git revision ``REV`` (:mod:`harness.bench_baseline`, imported as ``NAME@REV``), and
each of those at every requested thread count. After a warm-up, each round calls every entry
once on the same frame (the timing protocol :func:`harness.timer.time_frame`, one timed call;
a temporal filter from the same history each time), in a new order every round
(:func:`harness.timer.round_order`), so that a change of the machine's load hits all of them
alike. Ratios are taken round by round (:data:`RATIO_COLUMNS`: this entry's time over the
other's in the same round, median and range over the rounds): against each peer, against the
first filter, against its floor, against itself at the first thread count and, for a
baseline, the current filter against ``NAME@REV``.

With ``balance`` the CPU time of each of the process's threads is read around every call
(:func:`harness.threads.thread_cpu_seconds`): ``busiest_share`` is the busiest thread's share
of the filter's CPU time over the rounds and ``thread_spread`` total / busiest, the speed-up
over one thread that the sharing allows on idle cores (a load-balance measure that other work
on the machine disturbs little). With ``steady`` = N the timed frame is frame N, every entry
having run frames 0 .. N-1 first (a temporal filter's steady state).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from contextlib import ExitStack
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from harness.bench import (
    BenchResult,
    BenchSetup,
    add_ratios,
    backend_note,
    bench_environment,
    bench_inputs,
    filter_memory,
    load_average,
    output_rmse,
    stage_row,
    thread_list,
    timing_row,
    typed_table,
)
from harness.bench_baseline import baseline_spec, module_name, plugin_path, resolve_revision, revision_tree
from harness.buffers import check_filter_output
from harness.cache import make_key
from harness.errors import filter_error, short_error
from harness.executors.base import Executor, Shared, WorkerContext, WorkUnit
from harness.floor import floor_of
from harness.jobs import GroupInputs
from harness.plan import Job
from harness.renders import RenderStore
from harness.threads import balance, thread_cpu_seconds, using_threads
from harness.timer import round_order, time_frame, timed_call

#: the per-round ratio table's columns: ``x`` = this entry's ms / the other's ms in the same round
RATIO_COLUMNS = ("filter", "threads", "other", "other_threads", "resolution", "rounds", "x_median", "x_min",
                 "x_max", "x_cpu_median")


@dataclass(frozen=True)
class Entry:
    """One thing a :class:`RoundsTask` times.

    Attributes
    ----------
    label : str
        Its name in the tables: ``NAME``, ``NAME@REV`` (a baseline) or ``floor(LABEL)``.
    job : Job
        The registered filter, its backend, parameters and resolution.
    threads : int or None
        Threads of every pool while it is built and called (None: as the worker is).
    role : str
        ``filter``, ``peer``, ``baseline`` or ``floor``.
    source : tuple of str
        For a baseline: (package folder, module name) of the revision's copy.
    """

    label: str
    job: Job
    threads: int | None = None
    role: str = "filter"
    source: tuple = ()

    @property
    def key(self) -> str:
        return f"{self.label}|{self.threads}"


@dataclass
class EntryMeasure:
    """What one entry measured: per-round times, the warm-up, its output's error and memory."""

    threads: int
    status: str = "ok"
    ms: list = field(default_factory=list)
    cpu_ms: list = field(default_factory=list)
    compile_ms: float = math.nan
    rmse: float = math.nan
    memory: tuple | None = None
    stage_ms: str = ""
    thread_cpu: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


@dataclass
class RoundsMeasure:
    """Every entry's :class:`EntryMeasure` by :attr:`Entry.key`, and each round's call order (keys)."""

    entries: dict = field(default_factory=dict)
    order: list = field(default_factory=list)


@dataclass
class RoundsTask(WorkUnit):
    """Every entry of one resolution, timed round by round in one worker (see the module docstring).

    Attributes
    ----------
    entries : list of Entry
    shared : Shared
        The resolution's :class:`harness.jobs.GroupInputs` (the last frame is the timed one).
    rounds : int
    score : bool
        Score each filter's last output's ``rmse`` against the last frame's reference.
    balance : bool
        Read each thread's CPU time around every call.
    """

    entries: list
    shared: Shared
    rounds: int = 5
    score: bool = False
    balance: bool = False
    timed = True

    @property
    def label(self) -> str:
        job = self.entries[0].job
        return f"{len(self.entries)} entries at {job.width}x{job.height}, {self.rounds} rounds"

    def run(self, context: WorkerContext, shared: GroupInputs) -> RoundsMeasure:
        measure = RoundsMeasure()
        built = {}
        for entry in self.entries:
            with using_threads(entry.threads) as count:
                mine = measure.entries[entry.key] = EntryMeasure(threads=count)
                try:
                    built[entry.key] = _build(context.registry, entry, shared.frames, mine)
                except (Exception, SystemExit) as exc:
                    mine.status = f"error: {filter_error(exc)}"
        entries = {e.key: e for e in self.entries}
        outputs = {}
        for r in range(self.rounds):
            order = round_order([k for k in entries if k in built], r)
            measure.order.append(order)
            for key in order:
                entry, mine = entries[key], measure.entries[key]
                spec, filt, shown = built[key]
                check = None if entry.role == "floor" else f"filter {entry.label!r}"
                with using_threads(entry.threads):
                    before = thread_cpu_seconds() if self.balance else {}
                    try:
                        _, outputs[key], timing, _ = time_frame(filt, spec, entry.job.backend, shown[-1], False, 1,
                                                                check=check)
                    except (Exception, SystemExit) as exc:
                        mine.status = f"error: {filter_error(exc)}"
                        del built[key]
                        continue
                    for tid, seconds in (thread_cpu_seconds() if self.balance else {}).items():
                        mine.thread_cpu[tid] = mine.thread_cpu.get(tid, 0.0) + seconds - before.get(tid, 0.0)
                mine.ms.append(timing["ms_median"])
                mine.cpu_ms.append(timing["cpu_ms_median"])
                mine.stage_ms = timing.get("stage_ms", "")
            context.progress(1)
        for key, (spec, _, shown) in built.items():
            entry, mine = entries[key], measure.entries[key]
            if entry.role == "floor":
                continue
            if self.score:
                mine.rmse = output_rmse(context.registry, outputs[key], shared, entry.job)
            with using_threads(entry.threads):
                try:
                    peak = filter_memory(spec, entry.job, shown)
                    mine.memory = (peak.traced, peak.rss)
                except (Exception, SystemExit) as exc:
                    mine.notes.append(f"memory not measured: {short_error(exc, 120)}")
        return measure


def _spec_of(registry, entry: Entry):
    """The spec an entry times (a baseline's from its copied package; a floor's from its owner)."""
    name = entry.job.filter
    if entry.source:
        folder, module = entry.source
        return baseline_spec(folder, module, name, entry.label.removeprefix("floor(").removesuffix(")"))
    return registry.get("filter", name)


def _build(registry, entry: Entry, frames, mine: EntryMeasure) -> tuple:
    """(spec, primed filter, what it sees of each frame): built, run over every frame but the last,
    and warmed up on the last one's layout (``mine.compile_ms``: the first call's wall time)."""
    spec = _spec_of(registry, entry)
    job = entry.job
    shown = [f.subset((spec.requires | spec.optional) & f.channels) for f in frames]
    if entry.role == "floor":  # not validated: its output is a sum, infinite where an input is
        filt, spec = floor_of(spec)
        check = None
    else:
        filt = spec.factory(backend=job.backend, **job.param_dict)
        check = f"filter {entry.label!r}"
    filt.reset()
    for t, frame in enumerate(shown[:-1]):
        out, ms, _ = timed_call(lambda f=frame: filt(f, sampler=None), cuda=job.backend == "cuda")
        if check is not None:
            check_filter_output(out, frame, owner=check)
        if t == 0:
            mine.compile_ms = ms
    _, _, timing, _ = time_frame(filt, spec, job.backend, shown[-1], True, 1, check=check)
    if len(shown) == 1:
        mine.compile_ms = timing["compile_ms"]
    return spec, filt, shown


def entries_for(specs: Sequence, configured: Mapping, roles: Mapping[str, str], *, task: str, scene: str,
                renderer: str, backend: str, size: tuple[int, int], frames: int, threads: Sequence[int | None],
                baselines: Mapping[str, tuple] = (), floors: bool = True) -> list[Entry]:
    """The entries of one resolution: each filter and peer, each baseline (after its filter),
    each floor (CPU backend), at each thread count. A peer without ``backend`` is timed on its
    first own backend (the CPU)."""
    entries = []
    for count in threads:
        for spec in specs:
            params, preset = configured[spec.name]
            own = spec.backends[0] if roles[spec.name] == "peer" and backend not in spec.backends else backend
            job = Job(task, scene, renderer, spec.name, own, json.dumps(params, sort_keys=True, default=str),
                      preset, 1, 0, width=size[0], height=size[1], frames=frames, repeats=1)
            mine = [Entry(spec.name, job, count, roles[spec.name])]
            if spec.name in baselines:
                rev, folder, module = baselines[spec.name]
                mine.append(Entry(f"{spec.name}@{rev}", job, count, "baseline", (folder, module)))
            entries += mine
            if floors and backend == "cpu":
                entries += [Entry(f"floor({e.label})", e.job, count, "floor", e.source) for e in mine]
    return entries


def _median(values) -> float:
    return float(np.median(values)) if len(values) else math.nan


def _per_round(a: Sequence[float], b: Sequence[float]) -> np.ndarray:
    """``a / b`` round by round (over the rounds both have)."""
    n = min(len(a), len(b))
    x, y = np.asarray(a[:n], np.float64), np.asarray(b[:n], np.float64)
    return np.divide(x, y, out=np.full(n, np.nan), where=y > 0)


def _rows(task: RoundsTask, measure: RoundsMeasure, metric: str | None) -> tuple[list, list, list]:
    """(table rows, stage rows, ratio rows) of one resolution."""
    job0 = task.entries[0].job
    res, pixels = f"{job0.width}x{job0.height}", job0.width * job0.height
    by_key = {e.key: e for e in task.entries}
    got = measure.entries
    rows, stages, ratios = [], [], []

    def ratio_row(key: str, other: str) -> None:
        mine, theirs = got.get(key), got.get(other)
        if mine is None or theirs is None or mine.status != "ok" or theirs.status != "ok":
            return
        x, x_cpu = _per_round(mine.ms, theirs.ms), _per_round(mine.cpu_ms, theirs.cpu_ms)
        if not len(x):
            return
        ratios.append({"filter": by_key[key].label, "threads": mine.threads, "other": by_key[other].label,
                       "other_threads": theirs.threads, "resolution": res, "rounds": len(x),
                       "x_median": float(np.median(x)), "x_min": float(np.min(x)), "x_max": float(np.max(x)),
                       "x_cpu_median": float(np.median(x_cpu))})

    counts = list(dict.fromkeys(e.threads for e in task.entries))
    bench_backend = next((e.job.backend for e in task.entries if e.role == "filter"), "cpu")
    firsts = [e.label for e in task.entries if e.role == "filter" and e.threads == counts[0]]
    for entry in task.entries:
        if entry.role == "floor":
            continue
        mine = got[entry.key]
        base = {"filter": entry.label, "resolution": res, "threads": mine.threads}
        if mine.status != "ok" or not mine.ms:
            rows.append({**base, "status": mine.status if mine.status != "ok" else "error: no timed call"})
            continue
        floor_key = f"floor({entry.label})|{entry.threads}"
        floor = got.get(floor_key)
        floor_ok = floor is not None and floor.status == "ok" and floor.ms
        floors = (_median(floor.ms), _median(floor.cpu_ms)) if floor_ok else (math.nan, math.nan)
        x_of_floor = ((_median(_per_round(mine.ms, floor.ms)), _median(_per_round(mine.cpu_ms, floor.cpu_ms)))
                      if floor_ok else (math.nan, math.nan))
        row = timing_row(base, ms=(_median(mine.ms), min(mine.ms), max(mine.ms)), cpu_ms=_median(mine.cpu_ms),
                         compile_ms=mine.compile_ms, floor=floors, x_of_floor=x_of_floor, memory=mine.memory,
                         pixels=pixels, notes=mine.notes)
        row["rounds"] = len(mine.ms)
        note = backend_note(entry.job.backend, bench_backend)
        if note:
            row["notes"] = "; ".join(n for n in (row["notes"], note) if n)
        if metric:
            row["rmse"] = mine.rmse
        if task.balance:
            row["busiest_share"], row["thread_spread"] = balance(mine.thread_cpu)
        rows.append(row)
        stage = stage_row(base, mine.stage_ms)
        if stage is not None:
            stages.append(stage)
        # the ratios: peers, the first filter, the floor, the first thread count, the baseline
        same = [e for e in task.entries if e.threads == entry.threads and e.key != entry.key]
        if entry.role == "filter":
            for other in same:
                if other.role == "peer" or (other.role == "filter" and firsts and other.label == firsts[0]):
                    ratio_row(entry.key, other.key)
            for other in same:
                if other.role == "baseline" and other.job.filter == entry.job.filter:
                    ratio_row(entry.key, other.key)
        if floor_ok:
            ratio_row(entry.key, floor_key)
        if entry.threads != counts[0]:
            ratio_row(entry.key, f"{entry.label}|{counts[0]}")
    return rows, stages, ratios


def bench_rounds(
    registry,
    store: RenderStore,
    executor: Executor,
    filters: Sequence[str],
    *,
    rounds: int,
    peers: Sequence[str] = (),
    baseline: str | None = None,
    balance: bool = False,
    steady: int = 0,
    floors: bool = True,
    scene: str = "synthetic-edges",
    renderer: str | None = None,
    task: str = "denoise",
    resolutions: Sequence[tuple[int, int]] = ((1280, 720),),
    threads: Sequence[int | None] = (None,),
    backend: str = "cpu",
    params: Mapping[str, Mapping] | None = None,
    presets: Mapping[str, str] | None = None,
    error: bool = True,
    progress: Callable[[str], None] | None = None,
) -> BenchResult:
    """Time ``filters``, ``peers``, floors and baselines in turn, ``rounds`` rounds, in one worker.

    Parameters are those of :func:`harness.bench.bench_filters`, and:

    rounds : int
        Rounds (>= 1): each calls every entry once.
    baseline : str, optional
        A git revision: each of ``filters`` is also timed as it was there (``NAME@REV``).
    balance : bool
        Record each thread's CPU time (``busiest_share``, ``thread_spread`` columns).
    steady : int
        Frames run before the timed one (0: one frame, two for temporal filters).
    floors : bool
        Time each entry's floor in the rounds too (CPU backend; default).

    Returns
    -------
    BenchResult
        With :attr:`~harness.bench.BenchResult.ratios` (:data:`RATIO_COLUMNS`) and ``order``.

    Raises
    ------
    ValueError
        For rounds or steady below range, an unknown revision, a filter not in the project's tree.
    """
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise ValueError(f"--rounds must be an integer >= 1, got {rounds!r}")
    threads = thread_list(threads)
    environment = bench_environment()
    setup = BenchSetup.of(registry, filters, peers, scene=scene, renderer=renderer, task=task, params=params,
                          presets=presets, steady=steady, error=error)
    names, specs, rname, rspec = setup.names, setup.specs, setup.renderer, setup.rspec
    configured, frames, metric, channels = setup.configured, setup.frames, setup.metric, setup.channels
    roles = {n: ("filter" if n in filters else "peer") for n in names}
    say = progress or (lambda line: None)
    rows, stages, ratios, order = [], [], [], {}
    with ExitStack() as stack:
        baselines = {}
        if baseline is not None:
            commit = resolve_revision(baseline)
            located = {n: plugin_path(registry, n) for n in dict.fromkeys(filters)}
            tree = stack.enter_context(revision_tree(commit, sorted({p for _, p in located.values()})))
            for n, (_, path) in located.items():
                baselines[n] = (baseline, str(tree / path), module_name(commit, n))
        for width, height in resolutions:
            sized = RenderStore(registry, store.cache, resolution=(width, height))
            inputs = bench_inputs(sized, scene, rname, rspec, frames, channels, with_reference=metric is not None)
            shared = Shared(make_key(bench=[scene, rname, width, height, frames]), inputs)
            entries = entries_for(specs, configured, roles, task=task, scene=scene, renderer=rname, backend=backend,
                                  size=(width, height), frames=frames, threads=threads, baselines=baselines,
                                  floors=floors)
            job = RoundsTask(entries, shared, rounds, score=metric is not None, balance=balance)
            for _, outcome in executor.run([job]):
                if not outcome.ok:
                    for e in entries:
                        if e.role != "floor":
                            rows.append({"filter": e.label, "resolution": f"{width}x{height}",
                                         "threads": e.threads or -1, "status": outcome.error})
                    continue
                got = _rows(job, outcome.value, metric)
                rows += got[0]
                stages += got[1]
                ratios += got[2]
                order[f"{width}x{height}"] = [[k.split("|")[0] + _at(k) for k in keys]
                                              for keys in outcome.value.order]
                for row in got[0]:
                    say(f"{row['filter']} at {row['resolution']}, {row['threads']} thread(s): "
                        + (f"{row['ms_median']:.4g} ms over {row['rounds']} rounds" if row["status"] == "ok"
                           else row["status"]))
    extra = ["rounds"] + (["busiest_share", "thread_spread"] if balance else [])
    table = typed_table(pd.DataFrame(rows), with_rmse=metric is not None, extra=extra)
    add_ratios(table, setup.peers, resolutions, threads)
    environment["load_end"] = load_average()
    ratio_table = pd.DataFrame(ratios, columns=list(RATIO_COLUMNS))
    return BenchResult(table, pd.DataFrame(stages), environment, ratios=ratio_table, order=order)


def _at(key: str) -> str:
    """`` (N t)`` for a key's thread count where one was set."""
    count = key.split("|")[1]
    return "" if count == "None" else f" ({count}t)"


__all__ = ["RATIO_COLUMNS", "Entry", "RoundsTask", "bench_rounds", "entries_for"]
