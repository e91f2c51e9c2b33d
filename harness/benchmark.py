"""One call that plans, runs and stores a benchmark: :func:`run_benchmark` (what ``denoise-bench run`` does).

The command line only parses options into this call's arguments and prints what it returns;
tests and scripts call it directly. The steps are those of docs/architecture.md: a profile
with the caller's overrides, the scene selection (registered scenes and scene folders), the
plan (:func:`harness.plan.make_plan`), an executor, and :func:`harness.run.run_plan`.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from harness.cache import Cache
from harness.estimate import check_plan
from harness.executors import DEFAULT_TIMEOUT_S, make_executor
from harness.executors.base import Executor, PluginOptions
from harness.plan import Plan, make_plan
from harness.plugins import load_plugins
from harness.profiles import DEFAULT_PROFILE, get_profile
from harness.renders import RenderStore, scene_selection
from harness.run import RunOutcome, run_plan
from harness.specs import TASKS


def run_benchmark(
    *,
    out: str | Path,
    registry=None,
    profile: str = DEFAULT_PROFILE,
    task: str = "all",
    scenes: Iterable[str] | None = None,
    scene_dirs: Iterable[str | Path] = (),
    scene_roots: Iterable[str | Path] = (),
    filters: Iterable[str] | None = None,
    metrics: Iterable[str] | None = None,
    renderer: str | None = None,
    backends: Iterable[str] = ("auto",),
    spp: Iterable[int] = (1,),
    seeds: Iterable[int] | None = None,
    frames: int | None = None,
    resolution: tuple[int, int] | None = None,
    reference_spp: int | None = None,
    reference_target: float | None = None,
    repeats: int | None = None,
    timing_at: Iterable[tuple[int, int]] | None = None,
    timing_scene: str | None = None,
    emitters: str = "exclude",
    params: Mapping[str, Mapping[str, Any]] | None = None,
    presets: Mapping[str, str] | None = None,
    grid: Mapping[str, Mapping[str, list]] | None = None,
    nonfinite: str = "raise",
    executor: str | Executor = "local",
    executor_options: Mapping[str, Any] | None = None,
    timeout: float = DEFAULT_TIMEOUT_S,
    disable: Iterable[str] = (),
    cache_dir: str | Path | None = None,
    use_cache: bool = True,
    max_hours: float | None = None,
    resume: bool = False,
    pictures: bool = False,
    report_frames: bool = False,
    save_outputs: bool = False,
    progress: bool = False,
    on_plan: Callable[[Plan, list], None] | None = None,
    on_executor: Callable[[Any], None] | None = None,
    renderer_settings: Mapping[str, Mapping[str, Any]] | None = None,
    on_note: Callable[[str], None] | None = None,
    on_used: Callable[[str, str], None] | None = None,
) -> RunOutcome:
    """Plan and run a benchmark; store its results in ``out`` and return them.

    Parameters
    ----------
    out : path
        Output folder (``results.parquet``, ``manifest.json``, ``jobs/``).
    registry : harness.Registry, optional
        The plugins (default: :func:`harness.load_plugins` with ``disable``).
    profile : str
        A run profile (:mod:`harness.profiles`); ``frames``, ``seeds``, ``resolution``,
        ``reference_spp``, ``reference_target``, ``repeats``, ``timing_at`` and ``timing_scene``
        override its values where given.
    task : {"denoise", "antialias", "all"}
    scenes, scene_dirs
        Registered scene names (default: the suite of the tasks) and scene folders.
    scene_roots : iterable of path
        Folders of scene folders (``--scene-root``): each sub-folder a plugin opens joins the run,
        like ``scene_dirs``, in the ``real`` tier, at the profile's ``real_resolution``.
    filters, metrics
        Names (default: every filter serving the tasks, every metric).
    renderer : str, optional
        One renderer for every scene (default: the preferred one per scene and task).
    backends, spp, seeds
        Filter backends (``cpu``, ``cuda``, ``auto``, ``all``), samples per pixel, seeds.
    emitters, params, presets, grid, nonfinite
        As the options of ``denoise-bench run`` of the same names.
    executor : {"local", "inline", "dask"} or Executor
        An executor's name (started for the run and closed after it), or a running executor
        (used as it is and left open: e.g. one cluster for several runs).
    executor_options : mapping, optional
        Extra keyword arguments of the executor (``scheduler``, ``workers`` for ``dask``).
    timeout : float
        Seconds a job may go without progress (``local``, ``dask``).
    disable : iterable of str
        Plugins left out of the jobs' workers (and of the default registry).
    cache_dir, use_cache
        The render cache (default ``datasets/cache``), or none; checked writable first.
    max_hours : float, optional
        Refuse the run when its rendering is estimated to take longer (hours). Work that cannot
        fit in this machine's memory is always refused; the estimate is kept in
        ``plan.settings["estimate"]`` (:func:`harness.estimate.check_plan`).
    resume, pictures, report_frames, save_outputs, progress
        As :func:`harness.run.run_plan`.
    on_plan : callable, optional
        Called with the plan and the scene specs before any work (e.g. to print it and its
        estimate's ``announcement``).
    on_executor : callable, optional
        Called with the executor once it is started (e.g. to print where it runs).
    renderer_settings : mapping, optional
        Renderer name -> keyword arguments of its factory (``--renderer-option``), recorded in
        ``plan.settings["renderer_settings"]``.
    on_note : callable, optional
        Called with each one-line note of the scene selection (sub-folders of a root that no
        plugin opens).
    on_used : callable, optional
        As :func:`harness.run.run_plan`.

    Returns
    -------
    RunOutcome
        The stored table, with the ``plan`` and the render ``store`` it was made with.
    """
    disable = list(disable)
    registry = registry if registry is not None else load_plugins(disable=disable)
    tasks = list(TASKS) if task == "all" else [task]
    chosen = get_profile(profile).with_overrides(
        resolution=resolution, frames=frames, seeds=tuple(seeds) if seeds is not None else None,
        reference_spp=reference_spp, reference_target=reference_target, repeats=repeats,
        timing=tuple(timing_at) if timing_at is not None else None, timing_scene=timing_scene,
    )
    filters = list(filters) if filters is not None else sorted(
        n for n, s in registry.filters.items() if s.tasks & set(tasks))
    _check_filters(registry, filters, params or {})
    store = RenderStore(registry, Cache(cache_dir, enabled=use_cache).check(), resolution=chosen.resolution,
                        renderer_settings=dict(renderer_settings or {}))
    notes: list = []
    specs = scene_selection(registry, store, list(scenes) if scenes is not None else None, list(scene_dirs), tasks,
                            scene_roots=list(scene_roots), real_resolution=chosen.real_resolution, notes=notes)
    for line in notes:
        if on_note is not None:
            on_note(line)
    metrics = list(metrics) if metrics is not None else sorted(registry.metrics)
    plan = make_plan(
        registry, store, specs, filters, metrics, tasks=tasks, renderer=renderer, backends=list(backends),
        spp=list(spp), seeds=list(chosen.seeds), frames=chosen.frames, params=dict(params or {}),
        presets=dict(presets or {}), repeats=chosen.repeats, reference_spp=reference_spp, nonfinite=nonfinite,
        sampled_reference_spp=chosen.reference_spp, reference_target=chosen.reference_target, emitters=emitters,
        timing_resolutions=chosen.timing, timing_scene=chosen.timing_scene, grid=dict(grid or {}),
    )
    plan.settings["profile"] = {**chosen.as_dict(), "name": profile}
    plan.settings["tiers"] = {s.name: s.tier for s in specs}
    plan.settings["renderer_settings"] = {name: store.renderer_settings(name)
                                          for name in sorted({g.renderer for g in plan.groups})}
    copies = 1 if getattr(executor, "name", executor) == "inline" else 3  # the group's inputs in a worker too
    plan.settings["estimate"] = check_plan(plan, store, copies=copies, max_hours=max_hours)
    if on_plan is not None:
        on_plan(plan, specs)
    if isinstance(executor, str):
        options = {"registry": registry, "plugins": PluginOptions(disable=disable), "timeout": timeout,
                   **dict(executor_options or {})}
        running = make_executor(executor, **options)
    else:
        running = contextlib.nullcontext(executor)
    with running as started:
        if on_executor is not None:
            on_executor(started)
        outcome = run_plan(registry, plan, store, started, out, resume=resume, pictures=pictures,
                           report_frames=report_frames, save_outputs=save_outputs, progress=progress,
                           on_used=on_used)
    outcome.plan, outcome.store = plan, store
    return outcome


def _check_filters(registry, filters, params) -> None:
    """Named filters and their parameters, checked before any scene is opened (opening scene folders
    takes seconds); the planner checks everything again."""
    for name in filters:
        registry.get("filter", name)
    for name, values in params.items():
        registry.get("filter", name).check_params(values)
