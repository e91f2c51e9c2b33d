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
