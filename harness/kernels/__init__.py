"""Building blocks for plugins' Numba kernels: ``from harness import kernels``.

Plugins import nothing from each other, only the harness's public API, so what more than one
plugin's kernels use lives here (see ``docs/architecture.md``, "Shared kernels"):

Fast math (:mod:`.fastexp`, :mod:`.fastlog`), from multiplies and adds only, so that a loop over
them vectorises (this machine's Numba has no SVML: a libm call per element keeps a loop scalar)
    :func:`exp_neg` (``exp(-d)``), :func:`exp2_minus` (``2**-t``), :func:`fast_log` (``log x``),
    and their constants ``LOG2E``, ``LN2``, ``EXP_NEG_CLAMP``, ``T_MAX``.
Bit casts (:mod:`.bits`)
    :func:`int32_bits_as_float32`, :func:`float32_bits_as_int32`, :func:`int64_bits_as_float64`,
    :func:`float64_bits_as_int64`.
Load balancing (:mod:`.schedule`)
    :func:`take` (an atomic task counter), :func:`take_range` and :func:`thread_count` (the
    loop that hands out ranges of rows or pixels from it).
Small images (:mod:`.serial`)
    :func:`serial_below`, a context manager running Numba on one thread below
    ``SERIAL_MAX_PIXELS`` pixels.
Backends
    :class:`BackendHandle`, what :func:`harness.load_backend` returns: a filter's backend
    module (or a library's device) that every copy of the filter shares.

The Numba functions are ``@njit(inline="always")`` or intrinsics: they compile into the caller,
with the caller's ``fastmath`` and error model, and the compile cache of every plugin is keyed
on this package's source too (:mod:`harness.numba_cache`).
"""

from harness.backends import BackendHandle
from harness.kernels.bits import (
    float32_bits_as_int32,
    float64_bits_as_int64,
    int32_bits_as_float32,
    int64_bits_as_float64,
)
from harness.kernels.fastexp import EXP_NEG_CLAMP, LN2, LOG2E, T_MAX, exp2_minus, exp_neg
from harness.kernels.fastlog import fast_log
from harness.kernels.schedule import take, take_range, thread_count
from harness.kernels.serial import SERIAL_MAX_PIXELS, serial_below

__all__ = [
    "BackendHandle",
    "EXP_NEG_CLAMP",
    "LN2",
    "LOG2E",
    "SERIAL_MAX_PIXELS",
    "T_MAX",
    "exp2_minus",
    "exp_neg",
    "fast_log",
    "float32_bits_as_int32",
    "float64_bits_as_int64",
    "int32_bits_as_float32",
    "int64_bits_as_float64",
    "serial_below",
    "take",
    "take_range",
    "thread_count",
]
