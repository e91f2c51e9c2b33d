"""The work units the harness hands to executors: jobs, and the frames and reference chunks they need.

A work unit with ``timed = True`` measures time (a job's timing protocol): an executor that shares a
machine between work units runs it with nothing else beside it (see :mod:`harness.executors.dask`).
"""

from __future__ import annotations

from dataclasses import dataclass

from harness.executors.base import Shared, WorkerContext, WorkUnit
from harness.jobs import GroupInputs, JobResult, run_job
from harness.plan import Job, MetricPlan


@dataclass
class JobUnit(WorkUnit):
    """Run one job (filter, timing protocol, metrics) on its group's inputs.

    Attributes
    ----------
    job : Job
    metrics : MetricPlan
    shared : Shared
        The group's :class:`harness.jobs.GroupInputs` (sent once per worker).
    keep_outputs : {"none", "first", "all"} or frozenset of int
        Which outputs come back with the rows (a set: those frame indices).
    """

    job: Job
    metrics: MetricPlan
    shared: Shared
    keep_outputs: str | frozenset = "none"
    timed = True

    @property
    def label(self) -> str:
        j = self.job
        return f"{j.filter}/{j.backend} on {j.scene}"

    def run(self, context: WorkerContext, shared: GroupInputs) -> JobResult:
        spec = context.registry.get("filter", self.job.filter)
        rspec = context.registry.renderers.get(self.job.renderer)
        renderer = None
        if spec.adaptive and rspec is not None and rspec.adaptive and shared.scene is not None:
            renderer = context.renderer(self.job.renderer, shared.renderer_settings)
        return run_job(context.registry, self.job, shared, self.metrics, renderer=renderer,
                       keep_outputs=self.keep_outputs, progress=context.progress)


@dataclass
class FrameUnit(WorkUnit):
    """Render one noisy frame where the work unit runs and return its arrays (:meth:`Frame.to_arrays`).

    The scene travels as the shared input (once per worker per scene); the client validates the
    frame and stores it in its cache.

    Attributes
    ----------
    scene : str
        The scene's name (for messages).
    renderer : str
    settings : dict
        The renderer's factory keyword arguments (an equal renderer is built on the worker).
    frame_index, spp, seed : int
    channels : list of str
    resolution : (width, height)
    shared : Shared
        The scene (key: its content hash).
    """

    scene: str
    renderer: str
    settings: dict
    frame_index: int
    spp: int
    seed: int
    channels: list
    resolution: tuple
    shared: Shared

    @property
    def label(self) -> str:
        return f"frame {self.frame_index} of {self.scene} ({self.renderer}, {self.spp} spp, seed {self.seed})"

    def run(self, context: WorkerContext, shared) -> dict:
        frame = context.renderer(self.renderer, self.settings).render(
            shared, self.frame_index, spp=self.spp, seed=self.seed, channels=frozenset(self.channels),
            resolution=tuple(self.resolution))
        return frame.to_arrays()


@dataclass
class ChunkUnit(WorkUnit):
    """The float64 sum of one range of a reference's samples (a renderer's ``accumulate``).

    The client adds the sums of a reference's chunks in sample order, so the reference is the
    same bit for bit wherever and in whatever order the chunks ran.

    Attributes
    ----------
    scene : str
        The scene's name (for messages).
    renderer : str
    settings : dict
        The renderer's factory keyword arguments.
    frame_index, first_sample, count, seed : int
    resolution : (width, height)
    shared : Shared
        The scene (key: its content hash).
    """

    scene: str
    renderer: str
    settings: dict
    frame_index: int
    first_sample: int
    count: int
    seed: int
    resolution: tuple
    shared: Shared

    @property
    def label(self) -> str:
        last = self.first_sample + self.count - 1
        return f"reference samples {self.first_sample}-{last} of {self.scene} frame {self.frame_index}"

    def run(self, context: WorkerContext, shared):
        import numpy as np

        total = context.renderer(self.renderer, self.settings).accumulate(
            shared, self.frame_index, first_sample=self.first_sample, count=self.count, seed=self.seed,
            resolution=tuple(self.resolution))
        context.progress(self.count)
        return np.asarray(total, np.float64)
