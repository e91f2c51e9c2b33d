"""Compute backends: which are available on this machine."""

from __future__ import annotations

import os


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


def load_backend(package: str, backend: str, supported, *, owner: str):
    """The backend module of a filter: the one dispatch convention of every built-in filter.

    A filter package keeps each backend's kernels in a module named after it (``cpu.py``,
    ``cuda.py``) with the same entry points; the filter object calls this once, in its
    constructor, and keeps the module.

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
    module
        ``importlib.import_module(f"{package}.{backend}")``.

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
    return importlib.import_module(f"{package}.{backend}")
