"""The ``inline`` executor: tasks run in this process, one after another (for debugging)."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

from harness.errors import short_error
from harness.executors.base import Executor, Outcome, WorkerContext, WorkUnit


class InlineExecutor(Executor):
    """Runs each task in the calling process.

    Parameters
    ----------
    registry : harness.Registry
        The plugins tasks use.

    Notes
    -----
    An exception becomes an error outcome; a segfault, a hang or ``os._exit`` in a plugin ends
    the run (use the ``local`` executor to isolate them).
    """

    name = "inline"

    def __init__(self, registry, **_ignored):
        self.registry = registry
        self._context = WorkerContext(registry)

    def run(
        self, tasks: Sequence[WorkUnit], progress: Callable[[int], None] | None = None
    ) -> Iterator[tuple[int, Outcome]]:
        context = self._context
        for index, task in enumerate(tasks):
            done = 0

            def tick(n: int) -> None:
                nonlocal done
                done += n
                if progress is not None:
                    progress(n)

            context.progress = tick
            try:
                value = task.run_held(context, task.shared.value if task.shared is not None else None)
            except Exception as exc:
                yield index, Outcome(False, error=f"{task.label}: {short_error(exc)}", progress=done)
                continue
            yield index, Outcome(True, value, progress=done)
