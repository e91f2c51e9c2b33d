"""Where work units run: in this process, in a persistent worker process, or on a Dask cluster.

A work unit (:class:`harness.executors.base.WorkUnit`) is a small picklable object with a ``run(context,
shared)`` method; large inputs common to several work units travel once as a :class:`Shared` value.
An executor takes a batch of work units and yields each :class:`Outcome` as it completes:

``inline``
    runs work units in this process (debugging; a crash or a hang of a plugin is the run's).
``local`` (the default)
    runs work units one at a time in a persistent worker subprocess, so compiled code stays warm
    between jobs; a hang past the timeout, a segfault, ``os._exit`` or the kernel's OOM kill
    become an error outcome naming what happened, and the worker is restarted.
``dask`` (where ``distributed`` is installed: ``pip install -e ".[dask]"``)
    runs work units on a ``dask.distributed`` cluster (a local cluster of worker processes, or a
    scheduler's address); see :mod:`harness.executors.dask` and docs/cluster.md.

:func:`make_executor` builds one by name.
"""

import importlib.util

from harness.executors.base import Executor, Outcome, Shared, WorkerContext, WorkUnit
from harness.executors.inline import InlineExecutor
from harness.executors.local import LocalExecutor

#: executor names -> classes, or factories (``dask`` is added where the optional extra is installed)
EXECUTORS = {"inline": InlineExecutor, "local": LocalExecutor}
DEFAULT_TIMEOUT_S = 600.0
#: every executor name, installed or not
EXECUTOR_NAMES = ("dask", "inline", "local")
#: what to do when ``dask`` is asked for and ``distributed`` is missing
DASK_MISSING = 'the dask executor needs the optional extra: pip install -e ".[dask]" (dask[distributed])'



def _dask_executor(**options) -> Executor:
    """A :class:`harness.executors.dask.DaskExecutor` (imported on use: ``distributed`` is slow to import)."""
    from harness.executors.dask import DaskExecutor

    return DaskExecutor(**options)


if importlib.util.find_spec("distributed") is not None:
    EXECUTORS["dask"] = _dask_executor


def make_executor(name: str, **options) -> Executor:
    """The executor called ``name`` (``inline``, ``local`` or ``dask``), built with ``options``.

    Raises ``ValueError`` for an unknown name, or for ``dask`` where it is not installed.
    """
    if name == "dask" and name not in EXECUTORS:
        raise ValueError(DASK_MISSING)
    if name not in EXECUTORS:
        raise ValueError(f"executor must be one of {list(EXECUTOR_NAMES)}, got {name!r}")
    return EXECUTORS[name](**options)


__all__ = [
    "DASK_MISSING",
    "DEFAULT_TIMEOUT_S",
    "EXECUTORS",
    "EXECUTOR_NAMES",
    "Executor",
    "InlineExecutor",
    "LocalExecutor",
    "Outcome",
    "Shared",
    "WorkUnit",
    "WorkerContext",
    "make_executor",
]
