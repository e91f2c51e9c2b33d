"""The planner: which jobs run, which channels to render, what is skipped and why.

A job is (scene, renderer, filter, backend, params, spp, seed). The planner renders only the
union of channels that the selected filters need, and turns every combination that a scene,
renderer or machine cannot serve into a skipped job with its reason, kept in the results.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from harness.backends import cuda_available, resolve_backend
from harness.cache import make_key, plain

#: renderers preferred for each scene kind when the user names none
PREFERRED_RENDERERS = {"mesh": ("pathtracer",), "procedural": ("synthetic",)}


@dataclass(frozen=True)
class Job:
    """One benchmark job; ``job_id`` is a digest of every field."""

    scene: str
    renderer: str
    filter: str
    backend: str
    params: str  # canonical JSON of the filter parameters
    preset: str
    spp: int
    seed: int

    @property
    def job_id(self) -> str:
        return make_key(**self.__dict__)[:20]

    @property
    def param_dict(self) -> dict:
        return json.loads(self.params)


@dataclass
class MetricPlan:
    """Metrics a group will score, and those skipped with their reason."""

    frame: list = field(default_factory=list)
    sequence: list = field(default_factory=list)
    skipped: dict = field(default_factory=dict)  # metric name -> reason


@dataclass
class Group:
    """Jobs sharing one render: (scene, renderer, spp, seed) and the channels to produce."""

    scene: str
    renderer: str
    spp: int
    seed: int
    channels: frozenset
    frames: int
    jobs: list = field(default_factory=list)
    metrics: MetricPlan = field(default_factory=MetricPlan)


@dataclass
class Plan:
    """What a run will do.

    Attributes
    ----------
    groups : list of Group
        Runnable jobs grouped by render.
    skipped : list of (Job, str)
        Jobs that cannot run here, with the reason.
    resolution : (int, int) or None
        Override of every scene's default resolution.
    """

    groups: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    resolution: tuple | None = None
    reference_spp: int | None = None

    @property
    def jobs(self) -> list:
        return [job for g in self.groups for job in g.jobs]


def choose_renderer(registry, scene_spec) -> str | None:
    """The renderer for a scene when the user names none: preferred, else the first compatible."""
    compatible = [n for n, r in sorted(registry.renderers.items()) if scene_spec.kind in r.scene_kinds]
    for name in PREFERRED_RENDERERS.get(scene_spec.kind, ()):
        if name in compatible:
            return name
    return compatible[0] if compatible else None


def filter_params(spec, preset: str | None, overrides: Mapping[str, Any]) -> tuple[dict, str]:
    """Defaults, then the named preset, then ``overrides``; unknown names raise ``ValueError``."""
    params = dict(spec.params)
    if preset:
        if preset not in spec.presets:
            raise ValueError(f"filter {spec.name!r} has no preset {preset!r}; presets: {sorted(spec.presets)}")
        params.update(spec.presets[preset])
    unknown = sorted(set(overrides) - set(params))
    if unknown:
        raise ValueError(f"filter {spec.name!r} has no parameter(s) {unknown}; parameters: {sorted(params)}")
    params.update(overrides)
    return params, preset or ""


def make_plan(
    registry,
    scenes,
    filters,
    metrics,
    *,
    renderer: str | None = None,
    backends=("auto",),
    spp=(1,),
    seeds=(0,),
    frames: int | None = None,
    resolution: tuple | None = None,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    presets: Mapping[str, str] | None = None,
    reference_spp: int | None = None,
    scene_frames: Mapping[str, int] | None = None,
) -> Plan:
    """Build the plan of a run.

    Parameters
    ----------
    registry : harness.Registry
    scenes : list of SceneSpec
    filters, metrics : list of str
        Filter and metric names (validated against the registry).
    renderer : str, optional
        Renderer for every scene; by default one per scene (:func:`choose_renderer`).
    backends : iterable of str
        ``cpu``, ``cuda``, ``auto`` (cuda where a GPU is present) or ``all`` (every backend the
        filter implements).
    spp, seeds : iterables of int
    frames : int, optional
        Cap on frames per scene.
    resolution : (width, height), optional
    params : mapping filter -> {param: value}
    presets : mapping filter -> preset name
    scene_frames : mapping scene -> frame count
        Frame counts of scenes opened from folders (SceneSpec.frames otherwise).

    Returns
    -------
    Plan
    """
    params = params or {}
    presets = presets or {}
    plan = Plan(resolution=resolution, reference_spp=reference_spp)
    filter_specs = [registry.get("filter", f) for f in filters]
    metric_specs = [registry.get("metric", m) for m in metrics]
    for extra in set(params) | set(presets):
        if extra not in filters:
            raise ValueError(f"parameters given for filter {extra!r}, which is not selected")
    configured = {f.name: filter_params(f, presets.get(f.name), params.get(f.name, {})) for f in filter_specs}

    for scene_spec in scenes:
        rname = renderer or choose_renderer(registry, scene_spec)
        rspec = registry.renderers.get(rname) if rname else None
        n_frames = (scene_frames or {}).get(scene_spec.name, scene_spec.frames)
        if frames is not None:
            n_frames = max(1, min(n_frames, frames))
        for s in spp:
            for seed in seeds:
                group = None
                for fspec in filter_specs:
                    fparams, preset = configured[fspec.name]
                    for backend in _backends_for(fspec, backends):
                        job = Job(
                            scene_spec.name,
                            rname or "",
                            fspec.name,
                            backend,
                            json.dumps(plain(fparams), sort_keys=True),
                            preset,
                            int(s),
                            int(seed),
                        )
                        reason = _skip_reason(scene_spec, rname, rspec, fspec, backend)
                        if reason:
                            plan.skipped.append((job, reason))
                            continue
                        if group is None:
                            group = Group(scene_spec.name, rname, int(s), int(seed), frozenset(), n_frames)
                        group.jobs.append(job)
                        group.channels = group.channels | ((fspec.requires | fspec.optional) & rspec.provides)
                if group is not None:
                    if "spp" in rspec.provides:
                        group.channels = group.channels | {"spp"}
                    group.metrics = _metric_plan(metric_specs, rspec, n_frames)
                    plan.groups.append(group)
    return plan


def _backends_for(fspec, backends) -> list[str]:
    out = []
    for b in backends:
        if b == "all":
            out.extend(fspec.backends)
        else:
            chosen = resolve_backend(b, fspec.backends)
            out.append(chosen or b)
    return list(dict.fromkeys(out))


def _skip_reason(scene_spec, rname, rspec, fspec, backend) -> str:
    if rspec is None:
        return (
            f"no renderer for scene kind {scene_spec.kind!r}" if not rname else f"renderer {rname!r} is not registered"
        )
    if scene_spec.kind not in rspec.scene_kinds:
        return f"renderer {rname!r} renders {sorted(rspec.scene_kinds)} scenes, not {scene_spec.kind!r}"
    missing = sorted(fspec.requires - rspec.provides)
    if missing:
        return f"filter {fspec.name!r} needs channel(s) {missing} that renderer {rname!r} does not provide"
    if backend not in fspec.backends:
        return f"filter {fspec.name!r} has no {backend!r} backend (has {list(fspec.backends)})"
    if backend == "cuda" and not cuda_available():
        return "cuda backend: no GPU on this machine (numba.cuda.is_available() is False)"
    return ""


def _metric_plan(metric_specs, rspec, n_frames) -> MetricPlan:
    mp = MetricPlan()
    for m in metric_specs:
        if not rspec.references:
            mp.skipped[m.name] = f"renderer {rspec.name!r} makes no references"
        elif n_frames < m.min_frames:
            mp.skipped[m.name] = f"needs >= {m.min_frames} frames, scene has {n_frames}"
        elif m.kind == "sequence":
            mp.sequence.append(m)
        else:
            mp.frame.append(m)
    return mp
