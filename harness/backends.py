"""Compute backends: which are available on this machine, and a filter's handle on its own."""

from __future__ import annotations

import os
from typing import Any


def cuda_simulated() -> bool:
    """True when Numba's CUDA simulator is on (``NUMBA_ENABLE_CUDASIM=1``)."""
    return os.environ.get("NUMBA_ENABLE_CUDASIM", "0") not in ("", "0")


def cuda_available() -> bool:
    """True when ``numba.cuda`` can run kernels: a real GPU, or the simulator."""
    if cuda_simulated():
        return True
    try:
        from numba import cuda

        return bool(cuda.is_available())
    except Exception:
        return False


def available_backends() -> tuple[str, ...]:
    """Backends usable here, CPU first."""
    return ("cpu", "cuda") if cuda_available() else ("cpu",)


def resolve_backend(requested: str, supported) -> str | None:
    """Pick a backend: ``auto`` means ``cuda`` where a real GPU is present and supported.

    Returns None when ``requested`` is ``auto`` and nothing fits.
    """
    if requested != "auto":
        return requested
    if "cuda" in supported and cuda_available() and not cuda_simulated():
        return "cuda"
    return "cpu" if "cpu" in supported else None


class BackendHandle:
    """A filter's compute backend (its module of kernels, or a library's device object), shared by
    every copy of the filter.

    Attribute access reaches the wrapped object (``handle.run(...)`` calls ``target.run``);
    ``copy.copy`` and ``copy.deepcopy`` return the handle itself. A filter that keeps its
    backend in a handle therefore deep-copies with the default ``copy.deepcopy`` (the harness
    copies temporal filters to time them from the same state), where a module or a native
    object would fail or be duplicated.

    Parameters
    ----------
    target : object
        What the handle stands for; also its attribute ``target``.
    """

    __slots__ = ("target",)

    def __init__(self, target: Any):
        self.target = target

    def __getattr__(self, name: str) -> Any:
        if name == "target":  # not set yet (a copy made without __init__)
            raise AttributeError(name)
        return getattr(self.target, name)

    def __copy__(self) -> BackendHandle:
        return self

    def __deepcopy__(self, memo) -> BackendHandle:
        return self

    def __repr__(self) -> str:
        return f"BackendHandle({self.target!r})"


def load_backend(package: str, backend: str, supported, *, owner: str) -> BackendHandle:
    """The backend module of a filter: the one dispatch convention of every built-in filter.

    A filter package keeps each backend's kernels in a module named after it (``cpu.py``,
    ``cuda.py``) with the same entry points; the filter object calls this once, in its
    constructor, and keeps the handle (copies of the filter share it).

    Parameters
    ----------
    package : str
        The filter's package (``__package__`` inside it).
    backend : str
        ``cpu`` or ``cuda`` (the harness resolves ``auto`` before building a filter).
    supported : iterable of str
        The backends the filter declares in its ``FilterSpec``.
    owner : str
        The filter's name, for messages.

    Returns
    -------
    BackendHandle
        On ``importlib.import_module(f"{package}.{backend}")``: its attributes are the module's.

    Raises
    ------
    ValueError
        For a backend the filter does not declare.
    RuntimeError
        For ``cuda`` on a machine where ``numba.cuda`` cannot run.
    """
    import importlib

    supported = tuple(supported)
    if backend not in supported:
        raise ValueError(f"{owner}: unsupported backend {backend!r}; choose from {supported}")
    if backend == "cuda" and not cuda_available():
        raise RuntimeError(f"{owner}: backend 'cuda' needs a CUDA GPU or NUMBA_ENABLE_CUDASIM=1")
    return BackendHandle(importlib.import_module(f"{package}.{backend}"))
