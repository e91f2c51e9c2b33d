"""Run one filter over one stress sequence, checking every call's output (the first one too).

This runs where it is called: in a worker process through :mod:`harness.stress.units` (the
CLI), or in the test process (the pytest battery of :mod:`harness.testing`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from harness.buffers import NonFiniteError, check_filter_output
from harness.errors import short_error
from harness.memory import MemoryWatch
from harness.stress.cases import Sequence, StressCase
from harness.stress.properties import Failure, Monitor

#: bytes per pixel one call may add to the process (large frames): 1 KiB, 8 GiB at 4K. It
#: catches allocations that grow with a window per pixel, not a careful budget.
MEMORY_PER_PIXEL = 1024


@dataclass
class CaseResult:
    """How a filter did on a case.

    Attributes
    ----------
    status : str
        ``pass``, ``rejected`` or what failed (the statuses of :mod:`harness.stress.table`).
    message : str
        What failed (or why the input was rejected), one line.
    frame : int
        The frame where it failed (-1 when none).
    calls : int
        Filter calls made.
    ms_median, ms_max : float
        Per-call wall time of the filter, milliseconds.
    peak_mb : float
        The largest growth of the process's resident memory during one filter call, MiB (NaN
        where unknown).
    height, width : int
        Size of the first frame.
    notes : str
        Extra measurements (the energy ratio of long sequences).
    """

    status: str = "pass"
    message: str = ""
    frame: int = -1
    calls: int = 0
    ms_median: float = math.nan
    ms_max: float = math.nan
    peak_mb: float = math.nan
    height: int = -1
    width: int = -1
    notes: str = ""


def run_case(spec, backend: str, params: dict, case: StressCase, progress: Callable[[int], None] | None = None
             ) -> CaseResult:
    """Run the filter ``spec`` (built with ``backend`` and ``params``) over ``case``."""
    return run_sequence(spec, backend, params, case.sequence(spec), flat=case.flat, energy=case.energy,
                        fresh=case.fresh, rejects=case.rejects, memory_bound=case.memory,
                        progress=progress)


def run_sequence(spec, backend: str, params: dict, sequence: Sequence, *, flat: bool = False, energy: bool = False,
                 fresh: bool = False, rejects: bool = False, memory_bound: bool = False,
                 progress: Callable[[int], None] | None = None) -> CaseResult:
    """Run a filter over ``sequence``, checking the properties after every call.

    Parameters
    ----------
    spec : FilterSpec
    backend : str
    params : dict
        Filter parameters (validated by the caller).
    sequence : Sequence
    flat, energy, fresh, rejects : bool
        The case's properties (:class:`harness.stress.cases.StressCase`).
    memory_bound : bool
        Fail a call that grows the process by more than ``MEMORY_PER_PIXEL`` bytes per pixel.
    progress : callable, optional
        Called with 1 after each frame (a worker reports it, so a long case is not a hang).

    Returns
    -------
    CaseResult
        The first failure, or ``pass`` with the timings.
    """
    tick = progress or (lambda n: None)
    result = CaseResult()
    memory = _PeakMemory(traced=memory_bound)
    try:
        filt = spec.factory(backend=backend, **params)
        filt.reset()
    except (Exception, SystemExit) as exc:
        return _failed(result, Failure("error", f"filter could not be built: {_why(exc)}"), [], memory)
    monitor = Monitor(convex=spec.convex, flat=flat, energy=energy, clean_mean=sequence.clean_mean,
                      range_gain=getattr(spec, "range_gain", 4.0), range_radius=getattr(spec, "range_radius", None))
    visible = spec.requires | spec.optional
    times: list[float] = []
    for t, frame in enumerate(sequence):
        frame = frame.subset(visible & frame.channels)
        if t == 0:
            result.height, result.width = frame.shape
        if t in sequence.resets:
            filt.reset()
            monitor.restart()
        memory.before_call()
        start = time.perf_counter_ns()
        try:
            out = filt(frame, sampler=None)
            if backend == "cuda":
                from numba import cuda

                cuda.synchronize()
        except (Exception, SystemExit) as exc:
            memory.after_call()
            if rejects and isinstance(exc, ValueError):
                result.status, result.message, result.frame = "rejected", short_error(exc), t
                return _finish(result, times, memory)
            return _failed(result, Failure("error", f"frame {t}: {_why(exc)}", t), times, memory)
        times.append((time.perf_counter_ns() - start) / 1e6)
        grown = memory.after_call()
        result.calls += 1
        try:
            check_filter_output(out, frame, owner=f"filter {spec.name!r}")
        except NonFiniteError:
            pass  # the monitor says where, and whether the input was finite there
        except Exception as exc:
            return _failed(result, Failure("error", f"frame {t}: {short_error(exc)}", t), times, memory)
        failure = monitor.check(t, frame, np.asarray(out))
        if failure is None and memory_bound and grown * 2**20 > MEMORY_PER_PIXEL * frame.height * frame.width:
            failure = Failure("memory", f"the call grew the process by {grown:.0f} MiB, more than "
                                        f"{MEMORY_PER_PIXEL} bytes per pixel", t)
        if failure is None and fresh and t in sequence.resets:
            failure = _compare_fresh(spec, backend, params, frame, out, t)
        if failure is not None:
            return _failed(result, failure, times, memory)
        tick(1)
    failure = monitor.finish()
    result.notes = monitor.energy_summary()
    if failure is not None:
        return _failed(result, failure, times, memory)
    return _finish(result, times, memory)


def _compare_fresh(spec, backend, params, frame, out, t) -> Failure | None:
    other = spec.factory(backend=backend, **params)
    other.reset()
    want = other(frame, sampler=None)
    if not np.array_equal(np.asarray(out), np.asarray(want), equal_nan=True):
        diff = np.nanmax(np.abs(np.asarray(out, np.float64) - np.asarray(want, np.float64)))
        return Failure("reset_differs", f"after reset() the output differs from a fresh instance's "
                                        f"(max difference {diff:.3g})", t)
    return None


def _failed(result: CaseResult, failure: Failure, times, memory) -> CaseResult:
    result.status, result.message, result.frame = failure.status, failure.message, failure.frame
    return _finish(result, times, memory)


def _finish(result: CaseResult, times, memory) -> CaseResult:
    if times:
        result.ms_median = float(np.median(times))
        result.ms_max = float(max(times))
    result.peak_mb = memory.growth_mb()
    return result


def _why(exc: BaseException) -> str:
    if isinstance(exc, SystemExit):
        return f"SystemExit: the filter called sys.exit({exc.code!r})"
    return short_error(exc)


class _PeakMemory:
    """The largest growth of the process's memory during a filter call, MiB: the rise of the
    resident set size and, when ``traced`` (the memory-bound cases), the peak of the bytes
    :mod:`tracemalloc` saw allocated (NumPy's arrays among them), whichever is larger
    (:class:`harness.memory.MemoryWatch`); NaN where neither is measured.

    Building the case's frames is outside the calls, so it does not count. The traced peak keeps
    the bound where the resident size's high-water mark cannot be reset (a container without
    ``/proc/self/clear_refs``), where the bound would otherwise pass every call.
    """

    def __init__(self, traced: bool = False):
        self.peak = 0.0
        self.known = True
        self.traced = traced
        self.watch = MemoryWatch(traced=traced)

    def before_call(self) -> None:
        self.watch.start(resident=self.known)

    def after_call(self) -> float:
        """Growth during the call just made, MiB (and keep the largest)."""
        measured = self.watch.stop()
        growth = measured.rss / 2**20
        if math.isnan(growth):
            self.known = False
        if self.traced:
            traced = measured.traced / 2**20
            growth = traced if math.isnan(growth) else max(growth, traced)
        if not math.isnan(growth):
            self.peak = max(self.peak, growth)
        return growth

    def growth_mb(self) -> float:
        return self.peak if self.known or self.traced else math.nan
