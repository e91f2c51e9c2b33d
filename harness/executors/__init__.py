"""Where tasks run: in this process, in a persistent worker process, or on a Dask cluster.

A task (:class:`harness.executors.base.Task`) is a small picklable object with a ``run(context,
shared)`` method; large inputs common to several tasks travel once as a :class:`Shared` value.
An executor takes a batch of tasks and yields each :class:`Outcome` as it completes:

``inline``
    runs tasks in this process (debugging; a crash or a hang of a plugin is the run's).
``local`` (the default)
    runs tasks one at a time in a persistent worker subprocess, so compiled code stays warm
    between jobs; a hang past the timeout, a segfault, ``os._exit`` or the kernel's OOM kill
    become an error outcome naming what happened, and the worker is restarted.

:func:`make_executor` builds one by name.
"""

from harness.executors.base import Executor, Outcome, Shared, Task, WorkerContext
from harness.executors.inline import InlineExecutor
from harness.executors.local import LocalExecutor

#: executor names -> classes (``dask`` is added where the optional extra is installed)
EXECUTORS = {"inline": InlineExecutor, "local": LocalExecutor}
DEFAULT_TIMEOUT_S = 600.0


def make_executor(name: str, **options) -> Executor:
    """The executor called ``name`` (``inline`` or ``local``), built with ``options``.

    Raises ``ValueError`` for an unknown name.
    """
    if name not in EXECUTORS:
        raise ValueError(f"executor must be one of {sorted(EXECUTORS)}, got {name!r}")
    return EXECUTORS[name](**options)


__all__ = [
    "DEFAULT_TIMEOUT_S",
    "EXECUTORS",
    "Executor",
    "InlineExecutor",
    "LocalExecutor",
    "Outcome",
    "Shared",
    "Task",
    "WorkerContext",
    "make_executor",
]
