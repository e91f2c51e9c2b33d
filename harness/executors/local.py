"""The ``local`` executor: tasks run one at a time in a persistent worker subprocess.

The worker (:mod:`harness.executors.worker`) loads the same plugins as the parent and stays
alive between tasks, so compiled kernels stay warm. The parent watches it: a task that reports
no progress for ``timeout`` seconds is a hang (the worker is killed), and a worker that dies
(a segfault, ``os._exit``, the kernel's out-of-memory killer) turns its task into an error
outcome naming what happened. A new worker is started for the next task.

The worker runs the parent's code: it starts isolated (``python -I``: neither the current
directory nor ``PYTHON*`` variables shape its import path) with the parent's ``sys.path`` (in
the parent's current directory, so relative entries mean the same), and
reports where it imported ``harness`` from and the source hash of each plugin it loaded; a
worker that runs other code than the parent (whose manifest records the parent's) is an error,
never a silent substitute. It runs in its own process group, which is ended with it, so child
processes a plugin starts do not outlive it.

A task may define ``prepare(context)``: work done before the task's clock (compilation of a
filter's kernels, say), with its own limit ``prepare_timeout`` (seconds) instead of ``timeout``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from multiprocessing.connection import Connection
from pathlib import Path

from harness.executors.base import Executor, Outcome, PluginOptions, WorkUnit

#: seconds a new worker may take to load the plugins
START_TIMEOUT_S = 300.0
#: seconds a task's ``prepare`` may take when the task does not say (compilation on a loaded machine)
PREPARE_TIMEOUT_S = 1800.0
#: the worker's bootstrap: the parent's import path, then the worker's main (run with ``python -I -c``)
_BOOTSTRAP = ("import json, sys; sys.path[:] = json.loads(sys.argv[1]); "
              "from harness.executors.worker import main; sys.exit(main(sys.argv[2:]))")

_SIGNALS = {
    signal.SIGSEGV: "segmentation fault",
    signal.SIGBUS: "bus error",
    signal.SIGABRT: "aborted",
    signal.SIGILL: "illegal instruction",
    signal.SIGFPE: "floating-point exception",
    signal.SIGKILL: "killed; out of memory?",
}


class WorkerDied(RuntimeError):
    """The worker process ended while it held a task."""


class LocalExecutor(Executor):
    """One persistent worker subprocess.

    Parameters
    ----------
    registry : harness.Registry, optional
        Unused here (the worker loads its own); accepted so every executor is built alike.
    plugins : PluginOptions, optional
        How the worker loads plugins (the parent's disabled names and in-process modules).
    timeout : float
        Seconds a task may go without reporting progress before it counts as hung.
    """

    name = "local"

    def __init__(self, registry=None, *, plugins: PluginOptions | None = None, timeout: float = 600.0, **_ignored):
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 seconds, got {timeout!r}")
        self.registry = registry
        self.plugins = plugins or PluginOptions()
        self.timeout = float(timeout)
        self._proc: subprocess.Popen | None = None
        self._inbox: Connection | None = None
        self._outbox: Connection | None = None
        self._held = ""
        self.started = 0
        self.handoff_s: list[float] = []
        self.worker_code: dict = {}

    # ------------------------------------------------------------------ worker life
    def _start(self) -> None:
        read_child, write_parent = os.pipe()
        read_parent, write_child = os.pipe()
        env = dict(os.environ)
        env["DENOISE_HARNESS_PARENT"] = str(os.getpid())
        path = json.dumps([p for p in sys.path if isinstance(p, str)])  # the worker starts in this cwd
        try:
            self._proc = subprocess.Popen(
                [sys.executable, "-I", "-c", _BOOTSTRAP, path, str(read_child), str(write_child)],
                pass_fds=(read_child, write_child),
                stdin=subprocess.DEVNULL,
                stdout=sys.__stderr__.fileno() if sys.__stderr__ is not None else subprocess.DEVNULL,
                env=env,
                start_new_session=True,
            )
        finally:
            os.close(read_child)
            os.close(write_child)
        self._outbox = Connection(write_parent, readable=False)
        self._inbox = Connection(read_parent, writable=False)
        self._held = ""
        self.started += 1
        self._outbox.send(("init", self.plugins))
        message = self._receive(START_TIMEOUT_S, "starting the worker")
        if message[0] != "ready":
            raise WorkerDied(f"the worker could not start: {message[1]}")
        self._check_code(message[1])

    def _check_code(self, info: dict) -> None:
        """The worker must run this process's ``harness`` and the same source of every plugin both loaded."""
        import harness

        mine = str(Path(harness.__file__).resolve().parent)
        if info.get("harness") != mine:
            raise WorkerDied(f"the worker imported harness from {info.get('harness')}, this process from {mine}: "
                             "it would run other code than the run records")
        ours, theirs = {}, info.get("plugins", {})
        if self.registry is not None:
            ours = {f"{r.kind}:{r.name}": r.source_hash for r in self.registry.records if r.status == "ok"}
            differ = sorted(k for k in ours.keys() & theirs.keys() if ours[k] != theirs[k])
            if differ:
                raise WorkerDied(f"the worker loaded other source of plugin(s) {differ} than this process")
        self.worker_code = {"same_harness": True, "plugins_compared": len(ours.keys() & theirs.keys())}

    def _stop(self, kill: bool) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        if not kill and proc.poll() is None:
            try:
                self._outbox.send(("stop",))
                proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                kill = True
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        _end_group(proc.pid)
        for conn in (self._inbox, self._outbox):
            if conn is not None:
                conn.close()
        self._inbox = self._outbox = None
        self._held = ""

    def close(self) -> None:
        self._stop(kill=False)

    def _death(self) -> str:
        """Why the worker ended (it has, or is about to)."""
        proc = self._proc
        try:
            code = proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            code = proc.wait()
        if code < 0:
            sig = signal.Signals(-code)
            detail = _SIGNALS.get(sig, "signal")
            return f"the worker process died: {sig.name} ({detail})"
        return f"the worker process exited with code {code} (os._exit or a fatal error in a plugin)"

    def _receive(self, timeout: float, doing: str):
        """The next message, or :class:`WorkerDied` (hang past ``timeout``, or the worker ended)."""
        try:
            ready = self._inbox.poll(timeout)
        except (OSError, EOFError):
            ready = True
        if not ready:
            raise WorkerDied(f"timed out: no progress for {timeout:g} s while {doing} (worker killed)")
        try:
            return self._inbox.recv()
        except (EOFError, OSError):
            raise WorkerDied(self._death()) from None

    # ------------------------------------------------------------------ tasks
    def run(
        self, tasks: Sequence[WorkUnit], progress: Callable[[int], None] | None = None
    ) -> Iterator[tuple[int, Outcome]]:
        for index, task in enumerate(tasks):
            yield index, self._run_one(task, progress)

    def _run_one(self, task: WorkUnit, progress) -> Outcome:
        done = 0
        try:
            if self._proc is None:
                self._start()
            start = time.perf_counter()
            if task.shared is not None and task.shared.key != self._held:
                self._outbox.send(("shared", task.shared.key, task.shared.value))
                self._held = task.shared.key
            self._outbox.send(("task", task.without_shared()))
            self.handoff_s.append(time.perf_counter() - start)
            prepared = not callable(getattr(task, "prepare", None))
            while True:
                if prepared:
                    message = self._receive(self.timeout, task.label)
                else:
                    limit = getattr(task, "prepare_timeout", None) or max(PREPARE_TIMEOUT_S, self.timeout)
                    message = self._receive(limit, f"preparing {task.label}")
                if message[0] == "prepared":
                    prepared = True
                    continue
                if message[0] == "progress":
                    done += message[1]
                    if progress is not None:
                        progress(message[1])
                    continue
                if message[0] == "done":
                    return Outcome(True, message[1], progress=done)
                return Outcome(False, error=message[1], progress=done)
        except WorkerDied as exc:
            self._stop(kill=True)
            return Outcome(False, error=f"{task.label}: {exc}", progress=done)
        except (BrokenPipeError, ConnectionResetError):
            reason = self._death() if self._proc is not None else "the worker is gone"
            self._stop(kill=True)
            return Outcome(False, error=f"{task.label}: {reason}", progress=done)

    def describe(self) -> dict:
        return {"executor": self.name, "timeout_s": self.timeout, "workers_started": self.started,
                "worker_code": self.worker_code}


def _end_group(pgid: int) -> None:
    """Kill what is left of the worker's process group (child processes its plugins started)."""
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
