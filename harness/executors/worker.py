"""The worker process of the ``local`` executor: :func:`main` with ``READ_FD WRITE_FD``.

:class:`harness.executors.local.LocalExecutor` starts it isolated (``python -I``) with its own
``sys.path``, so the current directory cannot shadow the installed code. It reads pickled
messages from ``READ_FD`` and answers on ``WRITE_FD`` (both pipes from its parent); its standard
output goes to the parent's standard error, so a plugin that prints cannot corrupt the protocol.
Messages, parent to worker:

``("init", PluginOptions)``   load the plugins; answered ``("ready", {"pid", "machine", "harness",
                              "plugins"})``: the folder ``harness`` was imported from and the
                              source hash of each plugin loaded (``"kind:name"`` keys)
``("shared", key, value)``    keep a shared input (only the latest one is kept)
``("task", task)``            run it: first its ``prepare(context)`` where it has one, answered
                              ``("prepared",)``; then ``("progress", n)`` messages and
                              ``("done", value)`` or ``("failed", message)``
``("stop",)``                 exit

The worker ignores SIGINT (its parent stops it) and, on Linux, dies with its parent.
"""

from __future__ import annotations

import os
import signal
from multiprocessing.connection import Connection
from pathlib import Path


def _die_with_parent(parent: int) -> None:
    """Ask Linux to SIGKILL this process when its parent exits (best effort elsewhere)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)


def serve(inbox: Connection, outbox: Connection) -> None:
    """The worker loop (see the module docstring)."""
    from harness.errors import short_error
    from harness.executors.base import WorkerContext
    from harness.machine import machine_label

    context = None
    held: tuple[str, object] = ("", None)
    while True:
        try:
            message = inbox.recv()
        except (EOFError, OSError):
            return
        kind = message[0]
        if kind == "stop":
            return
        if kind == "init":
            try:
                registry = message[1].load()
            except Exception as exc:
                outbox.send(("failed", f"loading plugins: {short_error(exc)}"))
                return
            context = WorkerContext(registry, lambda n: outbox.send(("progress", n)))
            outbox.send(("ready", {"pid": os.getpid(), "machine": machine_label(), "harness": _harness_folder(),
                                   "plugins": {f"{r.kind}:{r.name}": r.source_hash for r in registry.records
                                               if r.status == "ok"}}))
        elif kind == "shared":
            held = (message[1], message[2])
        elif kind == "task":
            task = message[1]
            shared = held[1] if task.shared is not None and task.shared.key == held[0] else None
            try:
                prepare = getattr(task, "prepare", None)
                if callable(prepare):
                    prepare(context)
                    outbox.send(("prepared",))
                result = ("done", task.run_held(context, shared))
            except (Exception, SystemExit) as exc:
                result = ("failed", f"{task.label}: {short_error(exc)}")
            try:
                outbox.send(result)
            except Exception as exc:  # an unpicklable result
                outbox.send(("failed", f"{task.label}: its result could not be sent back: {short_error(exc)}"))


def _harness_folder() -> str:
    import harness

    return str(Path(harness.__file__).resolve().parent)


def main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent(int(os.environ.get("DENOISE_HARNESS_PARENT", os.getppid())))
    inbox = Connection(int(argv[0]), writable=False)
    outbox = Connection(int(argv[1]), readable=False)
    try:
        serve(inbox, outbox)
    except (BrokenPipeError, EOFError):
        pass
    return 0
