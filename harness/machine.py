"""What machine this process runs on: CPU, cores, threads, GPU (recorded with every timing)."""

from __future__ import annotations

import functools
import os
import platform
from pathlib import Path


@functools.lru_cache(maxsize=1)
def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what ``platform`` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


@functools.lru_cache(maxsize=1)
def gpu_name() -> str:
    """The CUDA GPU's name, or "" (the simulator counts as no GPU)."""
    from harness.backends import cuda_simulated

    if cuda_simulated():
        return ""
    try:
        from numba import cuda

        if not cuda.is_available():
            return ""
        name = cuda.get_current_device().name
        return name.decode() if isinstance(name, bytes) else str(name)
    except Exception:
        return ""


def machine_info() -> dict:
    """CPU, cores, Numba threads, GPU, host name and platform of this process's machine."""
    import numba

    return {
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "gpu": gpu_name(),
        "host": platform.node(),
        "platform": platform.platform(),
    }


def machine_label() -> str:
    """A short label for result rows: ``CPU model, N cores[, GPU]``."""
    parts = [cpu_model(), f"{os.cpu_count()} cores"]
    if gpu_name():
        parts.append(gpu_name())
    return ", ".join(parts)
