"""A benchmark run: a plan's groups rendered through the store, jobs handed to an executor, rows stored.

The data flow (docs/architecture.md): plan -> render store -> executor -> job -> rows ->
results. This module wires them and owns the output folder:

* the folder is locked for the run (a second run into it stops with the holder's name);
* each job's rows are written to ``DIR/jobs/<job_id>.parquet`` (atomically) as it finishes, and
  ``DIR/results.parquet`` is rewritten from them;
* with ``resume`` a stored job whose id (every input of its rows) is in the plan is kept, the
  rest is computed; stored jobs that the plan does not include are removed, so the folder holds
  exactly one plan's results;
* the manifest is written at the end however the run ends, and describes the stored table.

With an executor that runs tasks of several callers at once (``executor.concurrent``: the
``dask`` executor), every group runs in its own client thread: its frames and references are
rendered as tasks (:mod:`harness.remote_renders`), its jobs are submitted as soon as its inputs
are in, and each job's rows are stored as they arrive, so renders of one group overlap the jobs
of another and an interrupted run resumes as a local one does.
"""

from __future__ import annotations

import shutil
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from harness.cache import array_hash, clean_temporaries, make_key
from harness.errors import short_error
from harness.executors.base import Executor, Shared
from harness.exr import write_exr
from harness.images import write_pictures
from harness.jobs import GroupInputs, job_error_rows, skipped_row
from harness.lock import FolderLock, check_out_dir
from harness.manifest import make_manifest, provenance, write_manifest
from harness.nonfinite import apply_nonfinite_policy
from harness.plan import Group, Plan
from harness.real_resolutions import timing_frames
from harness.references import reference_record
from harness.remote_renders import RemoteRenders
from harness.renders import RenderStore
from harness.report import outputs as kept
from harness.results import write_table
from harness.rows import combine, make_table
from harness.units import JobUnit


@dataclass
class RunOutcome:
    """What a run did.

    Attributes
    ----------
    table : DataFrame
        The stored results (every job of the plan).
    reused : int
        Stored jobs kept (``resume``).
    removed : int
        Stored jobs removed because the plan does not include them.
    manifest : dict
    plan : Plan or None
        The plan that was run (set by :func:`harness.benchmark.run_benchmark`).
    store : RenderStore or None
        The render store it used (its cache counts hits and misses).
    """

    table: pd.DataFrame
    reused: int = 0
    removed: int = 0
    manifest: dict = field(default_factory=dict)
    plan: Plan | None = None
    store: RenderStore | None = None


def run_plan(
    registry,
    plan: Plan,
    store: RenderStore,
    executor: Executor,
    out_dir: str | Path,
    *,
    resume: bool = False,
    pictures: bool = False,
    report_frames: bool = False,
    save_outputs: bool = False,
    progress: bool = True,
    on_status: Callable[[str], None] | None = None,
    on_used: Callable[[str, str], None] | None = None,
) -> RunOutcome:
    """Run every job of ``plan`` and store the results in ``out_dir``.

    Parameters
    ----------
    registry : harness.Registry
    plan : harness.plan.Plan
    store : harness.renders.RenderStore
        The store the plan was made with.
    executor : harness.executors.Executor
        Where jobs run.
    out_dir : path
        Receives ``jobs/``, ``results.parquet``, ``manifest.json`` (and ``images/``).
    resume : bool
        Keep stored jobs whose identity is unchanged.
    pictures : bool
        Write PNGs of each job's first output, the input and the reference.
    report_frames : bool
        Keep three frames of each job of the first seed, its input and reference, for the
        report (:mod:`harness.report.outputs`).
    save_outputs : bool
        Write every output as a linear HDR OpenEXR file:
        ``DIR/outputs/<scene>/<filter>[-preset]-<backend>-spp<N>-seed<S>/<frame>.exr``.
    progress : bool
        Show a progress bar (frames) on standard error.
    on_status : callable, optional
        Receives one-line status messages (what is being rendered or run).
    on_used : callable, optional
        Called with ``("renderer", name)`` once a group's inputs are rendered and ``("filter",
        name)`` once a job has run (e.g. to say that a plugin's kernels are now compiled).

    Returns
    -------
    RunOutcome
    """
    out = check_out_dir(out_dir)
    with FolderLock(out):
        clean_temporaries(out)
        if store.cache.enabled:
            clean_temporaries(store.cache.root)
        run = _Run(registry, plan, store, executor, out, resume, pictures, save_outputs, progress, on_status)
        run.report_frames = report_frames
        run.used = on_used or (lambda kind, name: None)
        return run.execute()


class _Run:
    def __init__(self, registry, plan, store, executor, out, resume, pictures, save_outputs, progress, on_status):
        self.registry, self.plan, self.store, self.executor = registry, plan, store, executor
        self.out, self.jobs_dir = out, out / "jobs"
        self.resume, self.pictures, self.save_outputs, self.progress = resume, pictures, save_outputs, progress
        self.status = on_status or (lambda text: None)
        self.used = lambda kind, name: None
        self.tables: dict[str, pd.DataFrame] = {}
        self.reused = self.removed = 0
        self.report_frames = False
        self.concurrent = bool(getattr(executor, "concurrent", False))
        self.renders: RemoteRenders | None = None
        self._lock = threading.RLock()
        self._stopped = threading.Event()  # the run was interrupted: group threads store nothing more

    def execute(self) -> RunOutcome:
        source = provenance()  # the code that runs: the checkout may change before the run ends
        self.jobs_dir.mkdir(parents=True, exist_ok=True)
        stored = self._prune()
        if not self.resume:
            shutil.rmtree(self.out / kept.FOLDER, ignore_errors=True)
        from tqdm.auto import tqdm

        total = sum(len(g.jobs) * g.frames for g in self.plan.groups)
        bar = tqdm(total=total, disable=not self.progress, unit="frame", dynamic_ncols=True, leave=False)
        try:
            for job, reason in self.plan.skipped:
                self._store(job.job_id, make_table([skipped_row(job, reason)], self.plan.metric_names), final=False)
            if self.concurrent:
                self._run_groups_concurrently(stored, _LockedBar(bar, self._lock))
            else:
                for group in self.plan.groups:
                    self._run_group(group, stored, bar)
        finally:
            bar.close()
            table = combine(self.tables.values())
            write_table(table, self.out / "results.parquet")
            manifest = make_manifest(self.registry, table, settings=self.plan.settings,
                                     executor=self.executor.describe(), reused_jobs=self.reused,
                                     scene_approximations=self.store.scene_approximations(
                                         sorted(set(table.scene)) if len(table) else []),
                                     source=source)
            write_manifest(manifest, self.out / "manifest.json")
        return RunOutcome(table, self.reused, self.removed, manifest)

    def _prune(self) -> dict:
        """Stored job files to keep (``resume``); every other stored job file is removed."""
        wanted = {job.job_id for job in self.plan.jobs}
        keep = {}
        for path in self.jobs_dir.glob("*.parquet"):
            if self.resume and path.stem in wanted:
                keep[path.stem] = path
                continue
            path.unlink(missing_ok=True)
            if self.resume:
                self.removed += 1
        return keep

    def _store(self, job_id: str, table: pd.DataFrame, final: bool = True) -> None:
        with self._lock:
            if self._stopped.is_set():
                return
            write_table(table, self.jobs_dir / f"{job_id}.parquet")
            self.tables[job_id] = table
            if final:
                write_table(combine(self.tables.values()), self.out / "results.parquet")

    def _run_groups_concurrently(self, stored: dict, bar) -> None:
        """Every group in its own thread; renders and jobs are tasks of the (concurrent) executor."""
        groups = self.plan.groups
        if not groups:
            return
        self.renders = RemoteRenders(self.store, self.executor)
        pool = ThreadPoolExecutor(min(len(groups), 32), thread_name_prefix="harness-group")
        try:
            for future in [pool.submit(self._run_group, g, stored, bar) for g in groups]:
                future.result()
        finally:
            self._stopped.set()
            pool.shutdown(wait=False, cancel_futures=True)
            self.renders.close()

    def _run_group(self, group: Group, stored: dict, bar) -> None:
        pending = []
        for job in group.jobs:
            table = _read(stored.get(job.job_id))
            if table is not None:
                if "tier" not in table or (table["tier"] != job.tier).any():  # stored before rows had tiers
                    table["tier"] = job.tier  # a function of the scene, not part of the job's id
                    self._store(job.job_id, table, final=False)
                with self._lock:
                    self.tables[job.job_id] = table
                    self.reused += 1
                bar.update(group.frames)
            else:
                pending.append(job)
        if not pending:
            return
        self.status(f"render {group.scene}")
        bar.set_description(f"render {group.scene}")
        try:
            inputs = self._inputs(group, any(self.registry.filters[j.filter].adaptive for j in pending))
        except Exception as exc:
            for job in pending:
                self._store(job.job_id, make_table(job_error_rows(job, f"render failed: {short_error(exc)}"),
                                                   self.plan.metric_names))
                bar.update(group.frames)
            return
        self.used("renderer", group.renderer)
        key = make_key(group=[group.task, group.scene, group.renderer, group.spp, group.seed, sorted(group.channels),
                              group.frames, list(group.resolution), group.reference_spp, pending[0].scene_hash])
        report = self._report_frames(group, inputs)
        keep = "all" if self.save_outputs else ("first" if self.pictures else "none")
        if report and not self.save_outputs:
            keep = report | {0} if self.pictures else report
        tasks = [JobUnit(job, group.metrics, Shared(key, inputs), keep) for job in pending]
        for index, outcome in self.executor.run(tasks, progress=bar.update):
            if self._stopped.is_set():
                return
            job = pending[index]
            bar.set_description(tasks[min(index + 1, len(tasks) - 1)].label)
            if outcome.ok:
                rows, outputs = outcome.value.rows, outcome.value.outputs
            else:
                rows, outputs = job_error_rows(job, outcome.error, frame=min(outcome.progress, group.frames - 1)), {}
                bar.update(max(group.frames - outcome.progress, 0))
            self._store(job.job_id, make_table(rows, self.plan.metric_names))
            self.used("filter", job.filter)
            for t in report:
                if t in outputs:
                    kept.save(self.out, job.task, job.scene, kept.output_name(job), t, outputs[t])
            preset = f"-{job.preset}" if job.preset else ""
            if self.pictures and 0 in outputs:
                write_pictures(self.out / "images" / job.scene, f"{job.filter}{preset}-{job.backend}-spp{job.spp}",
                               outputs[0], inputs.frames[0]["color"], f"input-spp{job.spp}", inputs.references[0])
            if self.save_outputs:
                name = f"{job.filter}{preset}-{job.backend}-spp{job.spp}-seed{job.seed}"
                folder = self.out / "outputs" / job.scene / name
                for t, image in outputs.items():
                    write_exr(folder / f"{t:04d}.exr", image)

    def _report_frames(self, group: Group, inputs: GroupInputs) -> frozenset:
        """The frames the report keeps of this group's jobs (none but for the first seed); stores its inputs."""
        seeds = self.plan.settings.get("seeds") or [group.seed]
        if not self.report_frames or group.seed != seeds[0]:
            return frozenset()
        frames = frozenset(kept.kept_frames(group.frames))
        for t in frames:
            kept.save(self.out, group.task, group.scene, f"input-spp{group.spp}", t, inputs.frames[t]["color"])
            if inputs.references[t] is not None:
                kept.save(self.out, group.task, group.scene, "reference", t, inputs.references[t])
        return frames

    def _inputs(self, group: Group, adaptive: bool) -> GroupInputs:
        store = self.store
        rspec = self.registry.renderers[group.renderer]
        scene = store.scene(group.scene)
        nonfinite = self.plan.settings.get("nonfinite", "raise")
        inputs = GroupInputs([], [], [], [], channels=group.channels,
                             scene=scene if adaptive and rspec.adaptive else None,
                             renderer_settings=store.factory_settings(group.renderer))
        if self.concurrent:  # every frame and reference requested at once, rendered on workers
            frames = [self.renders.frame(scene, group.renderer, t, spp=group.spp, seed=group.seed,
                                         channels=group.channels) for t in range(group.frames)]
            refs = [self.renders.reference_record(scene, group.renderer, t, spp=group.reference_spp,
                                                  target=group.reference_target)
                    if rspec.references else None for t in range(group.frames)]
        for t in range(group.frames):
            if self.concurrent:
                frame, record = frames[t].result(), refs[t].result() if refs[t] is not None else None
            else:
                frame = store.frame(scene, group.renderer, t, spp=group.spp, seed=group.seed,
                                    channels=group.channels)
                record = (reference_record(store, scene, group.renderer, t, spp=group.reference_spp,
                                           target=group.reference_target) if rspec.references else None)
            frame, count = apply_nonfinite_policy(frame, nonfinite, owner=f"renderer {group.renderer!r}")
            ref = record.image if record is not None else None
            inputs.frames.append(frame)
            inputs.repaired.append(count)
            inputs.references.append(ref)
            inputs.reference_hashes.append(array_hash(ref) if ref is not None else "")
            inputs.reference_variances.append(record.variance if record is not None else None)
            inputs.reference_quality.append((record.spp, record.error) if record is not None else None)
        inputs.timing_frames = timing_frames(store, group, nonfinite)
        return inputs


class _LockedBar:
    """A progress bar updated from several threads."""

    def __init__(self, bar, lock):
        self.bar, self.lock = bar, lock

    def update(self, n: int = 1) -> None:
        with self.lock:
            self.bar.update(n)

    def set_description(self, text: str) -> None:
        with self.lock:
            self.bar.set_description(text)


def _read(path: Path | None) -> pd.DataFrame | None:
    if path is None:
        return None
    try:
        return pd.read_parquet(path)
    except Exception:  # an unreadable job file is recomputed
        return None
