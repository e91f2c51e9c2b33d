"""The ``dask`` executor: tasks run on a ``dask.distributed`` cluster (optional extra ``[dask]``).

Without a scheduler address it starts a ``LocalCluster`` of worker processes, one per core of
this machine, one task at a time each; with one (``--scheduler`` or ``$DASK_SCHEDULER_ADDRESS``)
it joins that cluster (``dask scheduler`` + ``dask worker``, ``dask-jobqueue`` on SLURM or PBS).
docs/cluster.md is the user's guide; here is how it works:

* **Tasks.** Each :class:`harness.executors.base.WorkUnit` is one Dask task that calls
  :func:`execute` on a worker. A worker process loads the plugins once (the parent's
  :class:`PluginOptions`), keeps renderer instances between tasks, and returns the task's value
  (rows, frame arrays, a float64 sum of samples) to the client; nothing is read from or written
  to a shared file system.
* **Shared inputs.** A :class:`Shared` value becomes one Dask task that returns it; the tasks
  that use it depend on it, so it travels to each worker once, and the scheduler can make it
  again if the worker holding it is lost (a scattered value could not be made again).
* **Faults.** A worker that dies while it runs a task (a killed process, a lost machine) has the
  task rescheduled on another worker; the scheduler gives up on a task that was running on
  ``allowed_failures + 1`` workers that died, and the task becomes an error outcome that names
  it. An exception in a task is an error outcome at once (it would fail again).
* **Timing.** A task with ``timed = True`` (a job's timing protocol) runs with nothing else of
  the harness beside it on its machine: every task takes a host-wide reader-writer lock (a file
  lock in the temporary folder, released by the kernel if the process dies), shared for
  rendering, exclusive for timing, and a waiting timed task keeps new tasks from starting. A
  timed task uses every Numba thread of its process; other tasks use their share of the cores.
  Where some workers declare the Dask resource ``timing`` (``dask worker --resources timing=1``),
  timed tasks run only on those.

``--timeout`` (a hung task) is not enforced here: Dask cannot stop a running task. Use the
``local`` executor to isolate filters that may hang.
"""

from __future__ import annotations

import contextlib
import copy
import os
import tempfile
import threading
import uuid
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import dask
import distributed

from harness.errors import short_error
from harness.executors.base import Executor, Outcome, PluginOptions, Shared, WorkerContext, WorkUnit

#: how many workers may die running one task before it is given up (scheduler of a local cluster)
ALLOWED_FAILURES = 3
#: seconds to wait for the first worker of a cluster given by address
CONNECT_TIMEOUT_S = 60.0
#: the Dask worker resource that marks workers allowed to run timed tasks
TIMING_RESOURCE = "timing"


def machine_cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


@dataclass(frozen=True)
class WorkerOptions:
    """What every task carries to its worker (small).

    Attributes
    ----------
    plugins : PluginOptions
        How the worker loads plugins (the client's disabled names and in-process modules).
    threads : int or None
        Numba threads of a task that is not timed (None: every thread of the process).
    """

    plugins: PluginOptions
    threads: int | None = None


# ---------------------------------------------------------------------- on the worker
_contexts: dict = {}
_contexts_lock = threading.Lock()


def _worker_context(plugins: PluginOptions) -> WorkerContext:
    """The worker process's context for these plugin options (loaded on first use)."""
    key = (tuple(plugins.disable), tuple(plugins.modules))
    with _contexts_lock:
        if key not in _contexts:
            _contexts[key] = WorkerContext(plugins.load())
        return _contexts[key]


@contextlib.contextmanager
def host_slot(exclusive: bool, folder: str | Path | None = None):
    """Hold this machine's harness slot: shared (rendering) or exclusive (timing).

    Two ``flock`` files in ``folder`` (default: the temporary folder): a turnstile that a waiting
    exclusive holder keeps closed so that new shared holders queue behind it, and the lock
    itself. The kernel releases both when the process dies. Where ``fcntl`` is missing
    (Windows) this does nothing.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    base = Path(folder) if folder is not None else Path(tempfile.gettempdir())
    user = os.getuid() if hasattr(os, "getuid") else 0
    with open(base / f"denoise-harness-{user}.turnstile", "a+b") as gate, open(
        base / f"denoise-harness-{user}.lock", "a+b"
    ) as lock:
        fcntl.flock(gate, fcntl.LOCK_EX)
        if exclusive:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX)
            finally:
                fcntl.flock(gate, fcntl.LOCK_UN)
        else:
            fcntl.flock(gate, fcntl.LOCK_UN)
            fcntl.flock(lock, fcntl.LOCK_SH)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def _set_threads(threads: int | None) -> None:
    import numba

    most = numba.config.NUMBA_NUM_THREADS
    numba.set_num_threads(most if threads is None else max(1, min(int(threads), most)))


def execute(task: WorkUnit, shared, options: WorkerOptions) -> tuple[bool, object, int]:
    """Run one task on a worker (what each Dask task calls).

    Returns
    -------
    (ok, value or one-line error, progress units the task reported)
    """
    base = _worker_context(options.plugins)
    done = 0

    def tick(n: int) -> None:
        nonlocal done
        done += n

    context = copy.copy(base)  # the worker's registry and renderers, this task's progress
    context.progress = tick
    with host_slot(exclusive=task.timed):
        _set_threads(None if task.timed else options.threads)
        try:
            return True, task.run_held(context, shared), done
        except (Exception, SystemExit) as exc:
            return False, f"{task.label}: {short_error(exc)}", done


def _hold(value):
    """A shared input as a Dask task's result."""
    return value


# ---------------------------------------------------------------------- on the client
class DaskExecutor(Executor):
    """Runs tasks on a Dask cluster, yielding each outcome as it completes.

    Parameters
    ----------
    registry : harness.Registry, optional
        Unused (workers load their own plugins); accepted so every executor is built alike.
    plugins : PluginOptions, optional
        How workers load plugins.
    scheduler : str, optional
        Address of a running scheduler (default ``$DASK_SCHEDULER_ADDRESS``); without one a
        ``LocalCluster`` is started.
    workers : int, optional
        Worker processes of the local cluster (default: one per core).
    allowed_failures : int
        Workers that may die running one task before it becomes an error (local cluster; a
        remote scheduler keeps its own ``distributed.scheduler.allowed-failures``).
    dashboard_address : str
        Where the local cluster serves its dashboard (``:0``: any free port).
    """

    name = "dask"
    #: tasks of several calls of :meth:`run` may be in flight at once (from several threads)
    concurrent = True

    def __init__(self, registry=None, *, plugins: PluginOptions | None = None, scheduler: str | None = None,
                 workers: int | None = None, allowed_failures: int = ALLOWED_FAILURES,
                 dashboard_address: str = ":8787", **_ignored):
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
            raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
        if isinstance(allowed_failures, bool) or not isinstance(allowed_failures, int) or allowed_failures < 0:
            raise ValueError(f"allowed_failures must be an integer >= 0, got {allowed_failures!r}")
        self.address = scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS") or None
        self.cluster = None
        self._held: dict[str, list] = {}  # shared key -> [future, users]
        self._lock = threading.Lock()
        threads = None
        if self.address is None:
            count = workers or machine_cores()
            threads = max(1, machine_cores() // count)
            import logging

            with dask.config.set({"distributed.scheduler.allowed-failures": allowed_failures}):
                self.cluster = distributed.LocalCluster(
                    n_workers=count, threads_per_worker=1, processes=True, dashboard_address=dashboard_address,
                    silence_logs=logging.ERROR,
                )
            self.client = distributed.Client(self.cluster)
        else:
            try:
                self.client = distributed.Client(self.address, timeout=f"{CONNECT_TIMEOUT_S}s")
                self.client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
            except (OSError, TimeoutError, distributed.TimeoutError) as exc:
                raise ValueError(f"dask scheduler {self.address}: {short_error(exc)}") from None
        self.options = WorkerOptions(plugins or PluginOptions(), threads)
        self.allowed_failures = self.client.run_on_scheduler(_allowed_failures)

    # ------------------------------------------------------------------ what the user sees
    def workers(self) -> dict:
        """Address -> (host, threads, resources) of each connected worker."""
        info = self.client.scheduler_info(n_workers=-1)["workers"]
        return {addr: (w.get("host", ""), w.get("nthreads", 1), dict(w.get("resources") or {}))
                for addr, w in info.items()}

    @property
    def dashboard_link(self) -> str:
        return self.client.dashboard_link or ""

    def banner(self) -> str:
        """One line: where tasks run and the dashboard's address."""
        workers = self.workers()
        hosts = len({h for h, _, _ in workers.values()})
        where = "a local cluster" if self.cluster is not None else f"scheduler {self.address}"
        return (f"dask: {where}, {len(workers)} worker(s) on {hosts} machine(s); "
                f"dashboard {self.dashboard_link or 'unavailable (pip install bokeh)'}")

    def describe(self) -> dict:
        workers = self.workers()
        return {
            "executor": self.name,
            "scheduler": self.address or "local cluster",
            "workers": len(workers),
            "machines": len({h for h, _, _ in workers.values()}),
            "threads_per_worker": sorted({t for _, t, _ in workers.values()}),
            "allowed_failures": self.allowed_failures,
            "timing_resource": self._timing_resource(workers),
            "dask_version": distributed.__version__,
        }

    # ------------------------------------------------------------------ tasks
    def _timing_resource(self, workers=None) -> bool:
        return any(TIMING_RESOURCE in res for _, _, res in (workers or self.workers()).values())

    def _share(self, shared: Shared):
        """The Dask future holding a shared input (made once per key while some task uses it)."""
        with self._lock:
            entry = self._held.get(shared.key)
            if entry is None:
                with warnings.catch_warnings():
                    warnings.filterwarnings("ignore", message="Sending large graph")
                    future = self.client.submit(_hold, shared.value, key=f"shared-{shared.key[:24]}-{_token()}",
                                                pure=False)
                entry = self._held[shared.key] = [future, 0]
            entry[1] += 1
            return entry[0]

    def _unshare(self, key: str) -> None:
        with self._lock:
            entry = self._held.get(key)
            if entry is not None:
                entry[1] -= 1
                if entry[1] <= 0:
                    del self._held[key]

    def run(
        self, tasks: Sequence[WorkUnit], progress: Callable[[int], None] | None = None
    ) -> Iterator[tuple[int, Outcome]]:
        resources = {TIMING_RESOURCE: 1} if any(t.timed for t in tasks) and self._timing_resource() else None
        submitted: dict = {}  # future key -> (index, task, future)
        shared_keys = []
        try:
            for index, task in enumerate(tasks):
                value = None
                if task.shared is not None:
                    value = self._share(task.shared)
                    shared_keys.append(task.shared.key)
                future = self.client.submit(
                    execute, task.without_shared(), value, self.options, key=f"{type(task).__name__}-{_token()}",
                    pure=False, retries=0, resources=resources if task.timed else None,
                    priority=1 if task.timed else 0,  # a job whose inputs are in goes before more renders
                )
                submitted[future.key] = (index, task, future)
            for future in distributed.as_completed([f for _, _, f in submitted.values()]):
                index, task, _ = submitted.pop(future.key)
                outcome = self._outcome(future, task)
                if outcome.progress and progress is not None:
                    progress(outcome.progress)
                yield index, outcome
        finally:
            if submitted and self.client is not None:
                self.client.cancel([f for _, _, f in submitted.values()])
            for key in shared_keys:
                self._unshare(key)

    def _outcome(self, future, task: WorkUnit) -> Outcome:
        try:
            ok, value, done = future.result()
        except distributed.KilledWorker as exc:
            last = getattr(exc.last_worker, "address", exc.last_worker)
            return Outcome(False, error=(
                f"{task.label}: {exc.allowed_failures + 1} workers died running it (a crash, os._exit or an "
                f"out-of-memory kill); given up after {exc.allowed_failures} retries "
                f"(distributed.scheduler.allowed-failures); the last was {last}"))
        except Exception as exc:
            return Outcome(False, error=f"{task.label}: {short_error(exc)}")
        if ok:
            return Outcome(True, value, progress=done)
        return Outcome(False, error=value, progress=done)

    def close(self) -> None:
        with self._lock:
            self._held.clear()
        client, self.client = getattr(self, "client", None), None
        if client is not None:
            client.close()
        cluster, self.cluster = self.cluster, None
        if cluster is not None:
            cluster.close()


def _allowed_failures(dask_scheduler=None) -> int:
    return int(dask_scheduler.allowed_failures)


def _token() -> str:
    return uuid.uuid4().hex[:16]


__all__ = ["ALLOWED_FAILURES", "DaskExecutor", "WorkerOptions", "execute", "host_slot", "machine_cores"]
