"""The renderer's own cost of a frame at each spp, for equal-time comparisons.

A filter's time alone does not say what a frame costs: more samples per pixel cost render
time, a better filter costs filter time. For each task of a plan, the renderer of its timing
group (:func:`harness.plan.timing_group`: the timing scene, first seed) renders the scene's
first frame at each real timing resolution and at each spp of the run, with the channels the
group's filters receive, with the same protocol as filters (:func:`harness.timer.time_frame`):
one untimed call (compilation), then ``repeats`` timed calls, the median reported. The render
cache is bypassed (a cached frame costs nothing). The table is stored beside the results as
``render_cost.csv`` and :func:`harness.pareto.configuration_points` adds it to filter times.

An adaptive filter's extra samples are rendered inside its own timed calls, so its time
already counts them; its base samples are counted here like every other filter's.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import pandas as pd

from harness.machine import machine_label
from harness.plan import Plan, timing_group

#: the file of a run folder that holds the table
FILE = "render_cost.csv"
COLUMNS = ["task", "scene", "renderer", "spp", "seed", "width", "height", "channels", "render_ms",
           "render_ms_min", "render_ms_max", "repeats", "machine"]


def measure_render_cost(store, plan: Plan, *, resolutions=None, repeats: int | None = None,
                        clock=time.perf_counter) -> pd.DataFrame:
    """Time the renderer per frame at each spp of the plan and each timing resolution.

    Parameters
    ----------
    store : harness.renders.RenderStore
        The run's store (its scenes and renderer instances).
    plan : Plan
        A planned run; its ``settings`` give the timing resolutions, the timing scene and the
        repeats.
    resolutions : list of (width, height), optional
        Where to time (default: the plan's timing resolutions).
    repeats : int, optional
        Timed calls per frame (default: the plan's).
    clock : callable
        Seconds (a test passes a fake clock).

    Returns
    -------
    DataFrame
        One row per (task, spp, resolution) with :data:`COLUMNS`; empty without timing
        resolutions or groups.
    """
    repeats = int(repeats or plan.settings.get("repeats") or 3)
    if resolutions is None:
        resolutions = plan.settings.get("timing_resolutions") or []
    resolutions = [tuple(int(v) for v in r) for r in resolutions]
    rows = []
    for task in plan.settings.get("tasks", []):
        group = timing_group(plan, task, plan.settings.get("timing_scene"))
        if group is None or not resolutions:
            continue
        mine = [g for g in plan.groups if g.task == task and g.scene == group.scene and g.seed == group.seed]
        for spp in sorted({g.spp for g in mine}):
            channels = frozenset().union(*(g.channels for g in mine if g.spp == spp))
            for width, height in resolutions:
                times = _time_render(store.at_resolution((width, height)), group, spp, channels, repeats, clock)
                rows.append({"task": task, "scene": group.scene, "renderer": group.renderer, "spp": int(spp),
                             "seed": int(group.seed), "width": width, "height": height,
                             "channels": ",".join(sorted(channels)), "render_ms": statistics.median(times),
                             "render_ms_min": min(times), "render_ms_max": max(times), "repeats": repeats,
                             "machine": machine_label()})
    return pd.DataFrame(rows, columns=COLUMNS)


def _time_render(store, group, spp: int, channels, repeats: int, clock) -> list[float]:
    renderer = store.renderer(group.renderer)
    scene = store.scene(group.scene)
    resolution = store.resolution(scene)

    def render():
        renderer.render(scene, 0, spp=spp, seed=group.seed, channels=channels, resolution=resolution)

    render()  # compilation and first-touch costs stay out of the timings
    times = []
    for _ in range(repeats):
        start = clock()
        render()
        times.append((clock() - start) * 1000.0)
    return times


def write_render_cost(table: pd.DataFrame, out_dir: str | Path) -> Path:
    """Store the table as ``out_dir/render_cost.csv`` (an empty table removes a stored one: no stale costs)."""
    path = Path(out_dir) / FILE
    if table.empty:
        path.unlink(missing_ok=True)
    else:
        table.to_csv(path, index=False)
    return path


def read_render_cost(out_dir: str | Path) -> pd.DataFrame:
    """The stored table of a run folder (empty where the run has none)."""
    path = Path(out_dir) / FILE
    if not path.exists():
        return pd.DataFrame(columns=COLUMNS)
    return pd.read_csv(path)


__all__ = ["COLUMNS", "FILE", "measure_render_cost", "read_render_cost", "write_render_cost"]
