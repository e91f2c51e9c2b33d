"""The tasks the harness hands to executors."""

from __future__ import annotations

from dataclasses import dataclass

from harness.executors.base import Shared, Task, WorkerContext
from harness.jobs import GroupInputs, JobResult, run_job
from harness.plan import Job, MetricPlan


@dataclass
class JobTask(Task):
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

    @property
    def label(self) -> str:
        j = self.job
        return f"{j.filter}/{j.backend} on {j.scene}"

    def run(self, context: WorkerContext, shared: GroupInputs) -> JobResult:
        if shared is None:
            raise RuntimeError("the worker does not hold this job's inputs")
        spec = context.registry.get("filter", self.job.filter)
        rspec = context.registry.renderers.get(self.job.renderer)
        renderer = None
        if spec.adaptive and rspec is not None and rspec.adaptive and shared.scene is not None:
            renderer = context.renderer(self.job.renderer, shared.renderer_settings)
        return run_job(context.registry, self.job, shared, self.metrics, renderer=renderer,
                       keep_outputs=self.keep_outputs, progress=context.progress)
