"""The executor interface: work units, shared inputs, outcomes, and the context a work unit runs in."""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Shared:
    """A large input used by several work units, sent to a worker once per ``key``.

    An executor strips ``value`` from the work units it ships and sends it only to workers that do
    not hold ``key`` yet.
    """

    key: str
    value: Any = None


class WorkUnit(ABC):
    """A unit of work an executor runs: picklable, with its large inputs in :attr:`shared`.

    Attributes
    ----------
    shared : Shared or None
        The input several work units share (None when there is none).
    label : str
        What the work unit is, for progress and error messages.
    timed : bool
        The work unit measures time: an executor that shares a machine between work units runs it alone.
    """

    shared: Shared | None = None
    label: str = "task"
    timed: bool = False

    @abstractmethod
    def run(self, context: WorkerContext, shared: Any) -> Any:
        """Do the work; ``shared`` is ``self.shared.value`` as held by the worker."""

    def run_held(self, context: WorkerContext, shared: Any) -> Any:
        """:meth:`run`, refused (one line) where the unit has a shared input the worker does not hold;
        executors call this, so no work unit checks it itself."""
        if self.shared is not None and shared is None:
            raise RuntimeError(f"the worker does not hold the shared input of {self.label}")
        return self.run(context, shared)

    def without_shared(self) -> WorkUnit:
        """A copy without the shared value (what travels when the worker holds it)."""
        import copy

        clone = copy.copy(self)
        if self.shared is not None:
            clone.shared = Shared(self.shared.key)
        return clone


@dataclass
class Outcome:
    """How a work unit ended.

    Attributes
    ----------
    ok : bool
        The work unit returned (its value is in :attr:`value`).
    value : any
    error : str
        One line: what happened when not ``ok`` (an exception, a crash, a timeout).
    progress : int
        Progress units the work unit reported before it ended.
    """

    ok: bool
    value: Any = None
    error: str = ""
    progress: int = 0


@dataclass
class PluginOptions:
    """How a worker process loads plugins: the same as its parent's registry.

    Attributes
    ----------
    disable : list of str
        Plugin names disabled in the parent.
    modules : list of str
        Importable names of plugin modules registered in-process (``load_plugins(extra=...)``).
    """

    disable: list = field(default_factory=list)
    modules: list = field(default_factory=list)

    def load(self):
        """The registry these options describe."""
        import importlib

        from harness.plugins import load_plugins

        return load_plugins(disable=self.disable, extra=[importlib.import_module(m) for m in self.modules])


class WorkerContext:
    """What a work unit can use where it runs: the registry, renderer instances, a progress channel.

    Parameters
    ----------
    registry : harness.Registry
    progress : callable, optional
        Receives progress units (e.g. frames done) as the work unit reports them.
    """

    def __init__(self, registry, progress: Callable[[int], None] | None = None):
        self.registry = registry
        self.progress = progress or (lambda n: None)
        self._renderers: dict = {}

    def renderer(self, name: str, settings: dict | None = None):
        """A renderer instance, built once per (name, settings)."""
        settings = dict(settings or {})
        key = (name, json.dumps(settings, sort_keys=True, default=str))
        if key not in self._renderers:
            self._renderers[key] = self.registry.get("renderer", name).factory(**settings)
        return self._renderers[key]


class Executor(ABC):
    """Runs work units and reports each one's :class:`Outcome` as it completes.

    Use as a context manager (or call :meth:`close`) so workers are shut down.
    """

    name = "executor"

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @abstractmethod
    def run(
        self, tasks: Sequence[WorkUnit], progress: Callable[[int], None] | None = None
    ) -> Iterator[tuple[int, Outcome]]:
        """Run ``work units``; yield ``(index in work units, outcome)`` as each completes.

        Parameters
        ----------
        tasks : sequence of WorkUnit
        progress : callable, optional
            Called with progress units as work units report them (for a progress bar).
        """

    def close(self) -> None:  # noqa: B027 (optional: an executor without workers has nothing to release)
        """Release workers (idempotent)."""

    def describe(self) -> dict:
        """What the manifest records about where work units ran."""
        return {"executor": self.name}
