"""The planner: which jobs run, which channels to render, what is skipped and why.

A job is one filter configuration on one rendered sequence: (task, scene, renderer, filter,
backend, params, spp, seed) plus everything else that changes its rows (resolution, frames,
metrics and their versions, repeats, reference quality, versions and settings of the plugins,
the scene's content). Its id hashes all of it, so ``--resume`` reuses a stored job only when
nothing it depends on changed.

Tasks (DESIGN.md): a filter, a scene and a renderer each declare the tasks they serve; the
planner pairs a scene with a renderer for each selected task the scene declares, runs there the
filters that serve the task, and keeps every job a scene, renderer or machine cannot serve as a
skipped row with its reason. Jobs sharing (task, scene, renderer, spp, seed) form a group that
renders once: the union of the channels its filters and metrics need.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

from harness.backends import cuda_available, resolve_backend
from harness.cache import make_key, plain
from harness.rows import per_frame_column, timing_column
from harness.specs import TASKS
from harness.sweeps import grid_points

#: renderers preferred for each (scene kind, task) when the user names none
PREFERRED_RENDERERS = {
    ("mesh", "denoise"): ("pathtracer",),
    ("mesh", "antialias"): ("raster",),
    ("procedural", "denoise"): ("synthetic",),
    ("captured", "denoise"): ("captured",),
}
BACKEND_CHOICES = ("cpu", "cuda", "auto", "all")
#: the largest seed: seeds are stored in int64 columns
MAX_SEED = 2**63 - 1
EMITTER_CHOICES = ("exclude", "include")


@dataclass(frozen=True)
class Job:
    """One benchmark job; :attr:`job_id` is a digest of every field.

    The first fields name the job; the rest are inputs that change its rows and so belong to
    its identity (a stored job is reused only when all of them are equal).
    """

    task: str
    scene: str
    renderer: str
    filter: str
    backend: str
    params: str  # canonical JSON of the filter parameters
    preset: str
    spp: int
    seed: int
    scene_hash: str = ""
    scene_version: str = ""
    renderer_version: str = ""
    renderer_settings: str = "{}"
    filter_version: str = ""
    width: int = 0
    height: int = 0
    frames: int = 1
    metrics: tuple = ()  # (name, version) of every metric scored
    repeats: int = 0
    reference_spp: int = 0
    nonfinite: str = "raise"
    reference_target: float = 0.0  # median relative standard error the reference stops at (0: fixed spp)
    emitters: str = "exclude"  # emitter pixels in the error metrics: "exclude" or "include"
    timing: tuple = ()  # (width, height) the filter is also timed at (real resolutions), on this job
    tier: str = ""  # the scene's tier (SceneSpec.tier): a function of the scene, so not part of the id

    @property
    def job_id(self) -> str:
        identity = asdict(self)
        del identity["tier"]
        return make_key(**identity)[:20]

    @property
    def param_dict(self) -> dict:
        return json.loads(self.params)

    @property
    def resolution(self) -> tuple[int, int]:
        return (self.width, self.height)


@dataclass
class MetricPlan:
    """Metrics a group scores (by name), and those skipped with their reason."""

    frame: list = field(default_factory=list)
    sequence: list = field(default_factory=list)
    skipped: dict = field(default_factory=dict)  # metric name -> reason
    per_frame: list = field(default_factory=list)  # sequence metrics also scored per frame (their spec's per_frame)

    @property
    def names(self) -> list[str]:
        """The metric columns of the group's rows (per-frame columns included)."""
        return [*self.frame, *self.sequence, *map(per_frame_column, self.per_frame), *self.skipped]


@dataclass
class Group:
    """Jobs sharing one render: (task, scene, renderer, spp, seed) and the channels to produce."""

    task: str
    scene: str
    renderer: str
    spp: int
    seed: int
    channels: frozenset
    frames: int
    resolution: tuple
    reference_spp: int
    jobs: list = field(default_factory=list)
    metrics: MetricPlan = field(default_factory=MetricPlan)
    reference_target: float = 0.0
    timing: tuple = ()  # real resolutions its jobs are timed at (one group per task and spp: timing_groups)


@dataclass
class Plan:
    """What a run will do.

    Attributes
    ----------
    groups : list of Group
        Runnable jobs grouped by render.
    skipped : list of (Job, str)
        Jobs that cannot run here, with the reason.
    notes : list of str
        One line each about choices the planner made (one seed for a deterministic renderer).
    settings : dict
        The planning inputs (tasks, resolution, frames, repeats, ...) for the manifest.
    """

    groups: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    settings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    @property
    def jobs(self) -> list:
        return [job for g in self.groups for job in g.jobs]

    @property
    def metric_names(self) -> list[str]:
        return list(dict.fromkeys(name for g in self.groups for name in g.metrics.names))


def choose_renderer(registry, scene_spec, task: str) -> str | None:
    """The renderer for a scene and task when the user names none: preferred, else the first that fits."""
    fits = [
        n for n, r in sorted(registry.renderers.items())
        if scene_spec.kind in r.scene_kinds and scene_spec.tier in r.scene_tiers and task in r.tasks
    ]
    for name in PREFERRED_RENDERERS.get((scene_spec.kind, task), ()):
        if name in fits:
            return name
    return fits[0] if fits else None


def filter_params(spec, preset: str | None, overrides: Mapping[str, Any]) -> tuple[dict, str]:
    """Defaults, then the named preset, then ``overrides``, all checked against the spec.

    Raises ``ValueError`` for an unknown preset or parameter, or a value out of its declaration.
    """
    params = dict(spec.params)
    if preset:
        if preset not in spec.presets:
            raise ValueError(f"filter {spec.name!r} has no preset {preset!r}; presets: {sorted(spec.presets)}")
        params.update(spec.presets[preset])
    params.update(spec.check_params(overrides))
    return params, preset or ""


def _configurations(spec, preset, overrides, grid) -> list[tuple[dict, str]]:
    """Every configuration (params, preset) of a filter: one, or one per point of its sweep grid."""
    out = []
    for point in grid_points(spec.name, overrides, grid):
        configuration = filter_params(spec, preset, point)
        if configuration not in out:
            out.append(configuration)
    return out


def check_choices(
    *, spp=(1,), seeds=(0,), frames=None, resolution=None, repeats=1, reference_spp=None, backends=("auto",)
) -> None:
    """Raise a one-line ``ValueError`` for any value out of range (the CLI checks the same)."""

    def ints(name, values, low, high=None):
        for v in values:
            if isinstance(v, bool) or not isinstance(v, int) or v < low or (high is not None and v > high):
                within = f">= {low}" if high is None else f"in [{low}, 2**63 - 1]"
                raise ValueError(f"{name} must be integers {within}, got {v!r}")

    ints("spp", spp, 1)
    ints("seeds", seeds, 0, MAX_SEED)
    ints("repeats", [repeats], 1)
    if not spp or not seeds:
        raise ValueError("spp and seeds need at least one value each")
    if frames is not None:
        ints("frames", [frames], 1)
    if reference_spp is not None:
        ints("reference spp", [reference_spp], 1)
    if resolution is not None:
        ints("resolution", list(resolution), 1)
    bad = [b for b in backends if b not in BACKEND_CHOICES]
    if bad or not backends:
        raise ValueError(f"backend must be one of {BACKEND_CHOICES}, got {list(backends)}")


def make_plan(
    registry,
    store,
    scenes: Sequence,
    filters: Sequence[str],
    metrics: Sequence[str],
    *,
    tasks: Sequence[str] = TASKS,
    renderer: str | None = None,
    backends: Sequence[str] = ("auto",),
    spp: Sequence[int] = (1,),
    seeds: Sequence[int] = (0,),
    frames: int | None = None,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    presets: Mapping[str, str] | None = None,
    repeats: int = 3,
    reference_spp: int | None = None,
    nonfinite: str = "raise",
    sampled_reference_spp: int | None = None,
    reference_target: float = 0.0,
    emitters: str = "exclude",
    timing_resolutions: Sequence[tuple] = (),
    timing_scene: str | None = None,
    grid: Mapping[str, Mapping[str, Sequence[Any]]] | None = None,
) -> Plan:
    """Build the plan of a run.

    Parameters
    ----------
    registry : harness.Registry
    store : harness.renders.RenderStore
        Gives each scene's content hash, its resolution and each renderer's settings (they are
        part of every job's identity).
    scenes : list of SceneSpec
    filters, metrics : list of str
        Filter and metric names (validated against the registry).
    tasks : list of str
        Tasks to run (:data:`harness.specs.TASKS`).
    renderer : str, optional
        Renderer for every scene; by default one per scene and task (:func:`choose_renderer`).
    backends : list of str
        ``cpu``, ``cuda``, ``auto`` (cuda where a GPU is present) or ``all`` (every backend the
        filter implements).
    spp, seeds : list of int
    frames : int, optional
        Cap on frames per scene.
    params : mapping filter -> {param: value}
    presets : mapping filter -> preset name
    repeats : int
        Timed calls per frame.
    reference_spp : int, optional
        Samples per pixel of every reference (default: each renderer's ``reference_spp``).
    sampled_reference_spp : int, optional
        Samples per pixel of references that are sampled (renderers whose ``reference_spp`` is
        not 0) where ``reference_spp`` is not given: a profile's value, which leaves analytic
        references analytic.
    nonfinite : {"raise", "repair"}
        Policy for non-finite renderer output (part of the identity: it changes rows).
    reference_target : float
        Median relative standard error at which references stop (0: exactly ``reference_spp``,
        which is then the cap); see :mod:`harness.references`.
    emitters : {"exclude", "include"}
        Whether pixels whose first hit is an emitter count in the metrics that take a mask
        (excluded through the ``emission`` channel, which is then rendered).
    timing_resolutions : list of (width, height)
        Real resolutions every filter configuration is also timed at, per task and spp, on
        :func:`timing_groups`' groups (see :mod:`harness.real_resolutions`).
    timing_scene : str, optional
        The scene those timings are taken on, where it serves the task.
    grid : mapping filter -> {param: list of values}, optional
        Parameter sweeps: each filter runs every configuration of the cartesian product of its
        values (:func:`harness.sweeps.grid_points`), each configuration its own job.

    Returns
    -------
    Plan

    Raises
    ------
    ValueError, KeyError
        For unknown names, parameters out of their declared range, or invalid choices.
    """
    params = dict(params or {})
    presets = dict(presets or {})
    check_choices(spp=spp, seeds=seeds, frames=frames, repeats=repeats, reference_spp=reference_spp,
                  backends=backends)
    if sampled_reference_spp is not None:
        check_choices(reference_spp=sampled_reference_spp)
    for width, height in timing_resolutions:
        timing_column(int(width), int(height))  # raises for a resolution without a column
    if emitters not in EMITTER_CHOICES:
        raise ValueError(f"emitters must be one of {EMITTER_CHOICES}, got {emitters!r}")
    if isinstance(reference_target, bool) or not isinstance(reference_target, (int, float)) or not (
            0 <= reference_target < 1):
        raise ValueError(f"reference target must be a number in [0, 1), got {reference_target!r}")
    unknown_tasks = sorted(set(tasks) - set(TASKS))
    if unknown_tasks or not tasks:
        raise ValueError(f"task must be one of {TASKS}, got {list(tasks)}")
    if not filters:
        raise ValueError("no filters selected")
    if renderer is not None:
        registry.get("renderer", renderer)
    filter_specs = [registry.get("filter", f) for f in filters]
    metric_specs = [registry.get("metric", m) for m in metrics]
    grid = dict(grid or {})
    for extra in set(params) | set(presets) | set(grid):
        if extra not in filters:
            raise ValueError(f"parameters given for filter {extra!r}, which is not selected")
    configured = {f.name: _configurations(f, presets.get(f.name), params.get(f.name, {}), grid.get(f.name))
                  for f in filter_specs}
    metric_ids = tuple((m.name, m.version) for m in metric_specs)
    plan = Plan(settings={
        "tasks": list(tasks), "renderer": renderer, "backends": list(backends), "spp": list(spp),
        "seeds": list(seeds), "frames": frames, "resolution": store.resolution_override, "repeats": repeats,
        "reference_spp": reference_spp, "nonfinite": nonfinite, "filters": list(filters), "metrics": list(metrics),
        "sampled_reference_spp": sampled_reference_spp, "reference_target": reference_target, "emitters": emitters,
        "timing_resolutions": [list(r) for r in timing_resolutions], "timing_scene": timing_scene,
        # captured frames exist at one size only: never the scene timed at real resolutions
        "fixed_size_scenes": sorted(s.name for s in scenes if s.kind == "captured"),
        **({"grid": {f: {k: list(v) for k, v in g.items()} for f, g in grid.items()}} if grid else {}),
    })
    extra = {"reference_target": float(reference_target), "emitters": emitters}

    for scene_spec in scenes:
        for task in tasks:
            if task not in scene_spec.tasks:
                continue
            _plan_scene_task(plan, registry, store, scene_spec, task, renderer, filter_specs, configured, metric_specs,
                             metric_ids, backends=backends, spp=spp, seeds=seeds, frames=frames, repeats=repeats,
                             reference_spp=reference_spp, sampled_reference_spp=sampled_reference_spp,
                             nonfinite=nonfinite, extra=extra)
    if timing_resolutions:
        resolutions = tuple(tuple(int(v) for v in r) for r in timing_resolutions)
        for task in tasks:
            for group in timing_groups(plan, task, timing_scene):
                group.timing = resolutions
                group.jobs = [replace(job, timing=resolutions) for job in group.jobs]
    for fspec in filter_specs:
        if not any(job.filter == fspec.name for job in plan.jobs) and not any(
            job.filter == fspec.name for job, _ in plan.skipped
        ):
            job = Job(tasks[0], "", "", fspec.name, "", "{}", "", 0, 0, filter_version=fspec.version)
            served = sorted(set(fspec.tasks) & set(tasks))
            reason = (f"filter {fspec.name!r} serves {sorted(fspec.tasks)}; no selected scene is for that task"
                      if served else f"filter {fspec.name!r} serves {sorted(fspec.tasks)}, not {list(tasks)}")
            plan.skipped.append((job, reason))
    return plan


def timing_group(plan: Plan, task: str, scene: str | None = None) -> Group | None:
    """The group whose jobs also time their filter at real resolutions, for one task.

    The group of ``scene`` where it serves the task, else of the first scene planned for the
    task; of that scene, the group of the fewest samples per pixel and the first seed. Scenes
    that exist at one size only (captured frames) are never chosen. None when the task has no
    such group.
    """
    fixed = set(plan.settings.get("fixed_size_scenes", ()))
    groups = [g for g in plan.groups if g.task == task and g.scene not in fixed]
    if not groups:
        return None
    names = [g.scene for g in groups]
    chosen = scene if scene in names else names[0]
    mine = [g for g in groups if g.scene == chosen]
    low = min(g.spp for g in mine)
    return [g for g in mine if g.spp == low][0]


def timing_groups(plan: Plan, task: str, scene: str | None = None) -> list[Group]:
    """The groups whose jobs also time their filter at real resolutions, for one task: one per spp.

    The scene and seed of :func:`timing_group`, at every spp of the run (lowest first), so that
    each configuration is timed on its own spp's input (an adaptive filter's extra samples, or
    work that depends on the input's noise, differ between spp). A run with one spp times one
    group. Empty when the task has no timing group.
    """
    first = timing_group(plan, task, scene)
    if first is None:
        return []
    mine = [g for g in plan.groups if g.task == task and g.scene == first.scene and g.seed == first.seed]
    return [next(g for g in mine if g.spp == spp) for spp in sorted({g.spp for g in mine})]


def _plan_scene_task(plan, registry, store, scene_spec, task, renderer, filter_specs, configured, metric_specs,
                     metric_ids, *, backends, spp, seeds, frames, repeats, reference_spp, sampled_reference_spp,
                     nonfinite, extra) -> None:
    rname = renderer or choose_renderer(registry, scene_spec, task)
    rspec = registry.renderers.get(rname) if rname else None
    n_frames = scene_spec.frames if frames is None else max(1, min(scene_spec.frames, frames))
    width, height = store.resolution_of(scene_spec)
    ref_spp = 0
    if rspec is not None and rspec.references:
        ref_spp = reference_spp if reference_spp is not None else rspec.reference_spp
        if reference_spp is None and rspec.reference_spp and sampled_reference_spp is not None:
            ref_spp = sampled_reference_spp
    identity = {
        "scene_version": scene_spec.version,
        "width": width,
        "height": height,
        "frames": n_frames,
        "metrics": metric_ids,
        "repeats": repeats,
        "reference_spp": ref_spp,
        "nonfinite": nonfinite,
        **extra,
    }
    runnable = (rspec is not None and scene_spec.kind in rspec.scene_kinds and scene_spec.tier in rspec.scene_tiers
                and task in rspec.tasks)
    if runnable:
        identity.update(
            scene_hash=store.scene_hash(scene_spec.name),
            renderer_version=rspec.version,
            renderer_settings=json.dumps(plain(store.renderer_settings(rname)), sort_keys=True),
        )
    if rspec is not None and rspec.deterministic and len(seeds) > 1:
        plan.notes.append(f"scene {scene_spec.name!r}: renderer {rname!r} returns the same frames for every "
                          f"seed: one seed ({seeds[0]}) instead of {len(seeds)}")
        seeds = seeds[:1]
    for s in spp:
        for seed in seeds:
            group = None
            for fspec in filter_specs:
                if task not in fspec.tasks:
                    continue
                for backend, (fparams, preset) in itertools.product(_backends_for(fspec, backends),
                                                                    configured[fspec.name]):
                    job = Job(task, scene_spec.name, rname or "", fspec.name, backend,
                              json.dumps(plain(fparams), sort_keys=True), preset, int(s), int(seed),
                              filter_version=fspec.version, tier=scene_spec.tier, **identity)
                    reason = _skip_reason(scene_spec, task, rname, rspec, fspec, backend)
                    if reason:
                        plan.skipped.append((job, reason))
                        continue
                    if group is None:
                        group = Group(task, scene_spec.name, rname, int(s), int(seed), frozenset(), n_frames,
                                      (width, height), ref_spp, reference_target=float(extra["reference_target"]))
                    group.jobs.append(job)
                    group.channels = group.channels | ((fspec.requires | fspec.optional) & _provides(scene_spec, rspec))
            if group is not None:
                if "spp" in _provides(scene_spec, rspec):
                    group.channels = group.channels | {"spp"}
                if (extra["emitters"] == "exclude" and "emission" in rspec.provides
                        and any("mask" in m.accepts for m in metric_specs)):
                    group.channels = group.channels | {"emission"}  # the metrics' emitter mask
                group.metrics = _metric_plan(metric_specs, rspec, n_frames)
                plan.groups.append(group)


def _backends_for(fspec, backends) -> list[str]:
    out = []
    for b in backends:
        if b == "all":
            out.extend(fspec.backends)
        else:
            chosen = resolve_backend(b, fspec.backends)
            out.append(chosen or b)
    return list(dict.fromkeys(out))


def _skip_reason(scene_spec, task, rname, rspec, fspec, backend) -> str:
    if rspec is None:
        if rname:
            return f"renderer {rname!r} is not registered"
        return f"no renderer serves task {task!r} for scene kind {scene_spec.kind!r}"
    if scene_spec.kind not in rspec.scene_kinds:
        return f"renderer {rname!r} renders {sorted(rspec.scene_kinds)} scenes, not {scene_spec.kind!r}"
    if scene_spec.tier not in rspec.scene_tiers:
        return (f"renderer {rname!r} renders scenes of the {'/'.join(sorted(rspec.scene_tiers))} tier, not scene "
                f"{scene_spec.name!r} ({scene_spec.tier})")
    if task not in rspec.tasks:
        return f"renderer {rname!r} serves {sorted(rspec.tasks)}, not task {task!r}"
    missing = sorted(fspec.requires - rspec.provides)
    if missing:
        return f"filter {fspec.name!r} needs channel(s) {missing} that renderer {rname!r} does not provide"
    missing = sorted(fspec.requires - _provides(scene_spec, rspec))
    if missing:
        return f"filter {fspec.name!r} needs channel(s) {missing} that scene {scene_spec.name!r} does not have"
    if backend not in fspec.backends:
        return f"filter {fspec.name!r} has no {backend!r} backend (has {list(fspec.backends)})"
    if backend == "cuda" and not cuda_available():
        return "cuda backend: no GPU on this machine (numba.cuda.is_available() is False)"
    return ""


def _provides(scene_spec, rspec) -> frozenset:
    """Channels a group can have: the renderer's, limited by the scene's where it declares them."""
    if scene_spec.channels is None:
        return rspec.provides
    return rspec.provides & (scene_spec.channels | {"color"})


def _metric_plan(metric_specs, rspec, n_frames) -> MetricPlan:
    mp = MetricPlan()
    for m in metric_specs:
        if not rspec.references:
            mp.skipped[m.name] = f"renderer {rspec.name!r} makes no references"
        elif n_frames < m.min_frames:
            mp.skipped[m.name] = f"needs >= {m.min_frames} frames, scene has {n_frames}"
        elif m.kind == "sequence":
            mp.sequence.append(m.name)
            if m.per_frame:
                mp.per_frame.append(m.name)
        else:
            mp.frame.append(m.name)
    return mp
