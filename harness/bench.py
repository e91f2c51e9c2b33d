"""``denoise-bench bench``: per-frame filter time against peers measured in the same process.

Each resolution gets one rendered frame (two for temporal filters: the second is timed, with
history) from the render store; every filter, the peers included, runs the job runner's timing
protocol on that same frame, in the same worker (``local`` executor) or in this process
(``inline``). The table shows median/min/max milliseconds, the compile/warm-up call, RMSE
against the reference, and each filter's time relative to every peer (peer ms / filter ms: above
1 means faster than the peer).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import pandas as pd

from harness.cache import array_hash, make_key
from harness.executors.base import Executor, Shared
from harness.jobs import GroupInputs
from harness.plan import Job, MetricPlan, choose_renderer, filter_params
from harness.renders import RenderStore
from harness.tasks import JobTask

DEFAULT_PEERS = ("opencv_jbf", "oidn")


@dataclass
class BenchResult:
    """The timing table and the per-stage breakdowns of a bench."""

    table: pd.DataFrame
    stages: pd.DataFrame


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
    backend: str = "cpu",
    repeats: int = 10,
    params: Mapping[str, Mapping] | None = None,
    presets: Mapping[str, str] | None = None,
    error: bool = True,
) -> BenchResult:
    """Time ``filters`` and ``peers`` on the same frame at each resolution.

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
    backend : str
    repeats : int
        Timed calls per frame (>= 1).
    params, presets : mappings, optional
        As for :func:`harness.plan.make_plan`.
    error : bool
        Score each output's ``rmse`` against the renderer's reference (default). False skips
        the reference: the raster renderer's 8 x 8 SSAA reference is drawn whole, about 6 GB
        at 1280x720 and 13 GB at 1920x1080.

    Returns
    -------
    BenchResult
    """
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ValueError(f"repeats must be an integer >= 1, got {repeats!r}")
    peers = [p for p in peers if p not in filters]
    names = list(dict.fromkeys([*filters, *peers]))
    specs = [registry.get("filter", n) for n in names]
    scene_spec = registry.get("scene", scene)
    rname = renderer or choose_renderer(registry, scene_spec, task)
    if rname is None:
        raise ValueError(f"no renderer serves task {task!r} for scene {scene!r}")
    rspec = registry.get("renderer", rname)
    configured = {s.name: filter_params(s, (presets or {}).get(s.name), (params or {}).get(s.name, {})) for s in specs}
    frames = 2 if any(s.temporal for s in specs) else 1
    metric = "rmse" if error and "rmse" in registry.metrics and rspec.references else None
    channels = frozenset().union(*[(s.requires | s.optional) & rspec.provides for s in specs])
    rows, stages = [], []
    for width, height in resolutions:
        sized = RenderStore(registry, store.cache, resolution=(width, height))
        inputs = _inputs(sized, scene, rname, rspec, frames, channels, with_reference=metric is not None)
        tasks = []
        for spec in specs:
            fparams, preset = configured[spec.name]
            job = Job(task, scene, rname, spec.name, backend, json.dumps(fparams, sort_keys=True, default=str),
                      preset, 1, 0, width=width, height=height, frames=frames, repeats=repeats)
            tasks.append(JobTask(job, MetricPlan(frame=[metric] if metric else []),
                                 Shared(make_key(bench=[scene, rname, width, height, frames]), inputs)))
        for index, outcome in executor.run(tasks):
            name = names[index]
            res = f"{width}x{height}"
            last = outcome.value.rows[-1] if outcome.ok else None
            if last is None or last.status != "ok":
                message = outcome.error if last is None else last.message
                rows.append({"filter": name, "resolution": res, "status": f"error: {message}"})
                continue
            first = outcome.value.rows[0]
            rows.append({
                "filter": name, "resolution": res, "ms_median": last.ms_median, "ms_min": last.ms_min,
                "ms_max": last.ms_max, "compile_ms": first.compile_ms,
                **({"rmse": last.metrics.get("rmse", math.nan)} if metric else {}), "status": "ok",
            })
            if last.stage_ms:
                stages.append({"filter": name, "resolution": res, **json.loads(last.stage_ms)})
    table = pd.DataFrame(rows)
    for peer in peers:
        if "ms_median" not in table:
            break
        peer_ms = table[table["filter"] == peer].set_index("resolution")["ms_median"]
        table[f"x_vs_{peer}"] = [
            peer_ms.get(r, math.nan) / ms if ms and ms == ms else math.nan
            for r, ms in zip(table["resolution"], table["ms_median"])
        ]
    return BenchResult(table, pd.DataFrame(stages))


def _inputs(store: RenderStore, scene: str, renderer: str, rspec, frames: int, channels,
            with_reference: bool) -> GroupInputs:
    inputs = GroupInputs([], [], [], [], channels=channels)
    for t in range(frames):
        inputs.frames.append(store.frame(scene, renderer, t, spp=1, seed=0, channels=channels))
        ref = store.reference(scene, renderer, t, spp=rspec.reference_spp) if with_reference else None
        inputs.references.append(ref)
        inputs.reference_hashes.append(array_hash(ref) if ref is not None else "")
        inputs.repaired.append(0)
    return inputs
