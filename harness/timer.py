"""The timing protocol: how one filter call on one frame is timed, at any resolution.

The first call of a filter on a new shape is its compile/warm-up, recorded as ``compile_ms``
and checked like every other call; then ``repeats`` calls are timed with
``time.perf_counter_ns`` and reported as median, min and max, with the median process CPU time
of the calls (``time.process_time_ns``: every thread of the process, the compiled kernels' too;
on a machine shared with other work it moves less than the wall clock). CUDA work is
synchronised before the clock stops. Validation happens outside the timed region. A temporal filter is deep-copied
before each timed call so that every repeat starts from the same history; the state after the
last repeat carries on to the next frame. An adaptive filter's timed call includes the extra
samples it asks for (a fresh sampler per call). :func:`time_real_resolutions` applies the
protocol to a group's frames at real resolutions (:mod:`harness.real_resolutions`).

The same clocks serve measurements outside a job (``denoise-bench bench --rounds`` and the
scripts in ``benchmarks/``): :func:`timed_call` times one call, :func:`alternate` times
several callables in turn, call by call, the order changed every round (:func:`round_order`), so
that a change of the machine's load hits all of them alike.
"""

from __future__ import annotations

import copy
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from harness.buffers import Frame, check_filter_output
from harness.errors import filter_error
from harness.plan import Job


def time_real_resolutions(spec, job: Job, inputs, renderer=None) -> tuple[dict, list]:
    """Per-frame time of the job's filter on the group's frames at real resolutions.

    ``inputs`` is the group's :class:`harness.jobs.GroupInputs`. For each (width, height) of
    ``inputs.timing_frames``: a fresh filter is built and called
    once on the first frame (compilation and, for a temporal filter, history), then timed on
    the last one with the timing protocol (:func:`time_frame`, ``job.repeats`` calls; an
    adaptive filter renders its extra samples at that resolution inside the timed calls).

    Returns
    -------
    times : dict
        (width, height) -> median milliseconds per frame.
    failures : list of str
        Notes for the resolutions that failed.
    """
    times, failures = {}, []
    visible = spec.requires | spec.optional
    for (w, h), frames in inputs.timing_frames.items():
        try:
            filt = spec.factory(backend=job.backend, **job.param_dict)
            filt.reset()
            for k, frame in enumerate(frames):
                make = None
                if spec.adaptive and renderer is not None and inputs.scene is not None:
                    make = sampler_factory(renderer, inputs, job, frame.meta.index, (w, h))
                shown = frame.subset(visible & frame.channels)
                repeats = job.repeats if k == len(frames) - 1 else 1
                filt, _, timing, _ = time_frame(filt, spec, job.backend, shown, False, repeats, make,
                                                check=f"filter {job.filter!r}")
            times[(w, h)] = timing["ms_median"]
        except (Exception, SystemExit) as exc:
            failures.append(f"timing at {w}x{h} failed: {filter_error(exc)}")
    return times, failures


def sampler_factory(renderer, inputs, job: Job, t: int, resolution):
    """A callable giving a fresh sampler of frame ``t`` at ``resolution`` (adaptive filters)."""
    def make():
        return renderer.sampler(inputs.scene, t, spp=job.spp, seed=job.seed, channels=inputs.channels,
                                resolution=resolution)

    return make


def time_frame(filt, spec, backend: str, frame: Frame, first: bool, repeats: int, sampler_factory=None,
               check: str | None = None):
    """The timing protocol for one frame.

    Parameters
    ----------
    filt : filter object
    spec : FilterSpec
    backend : str
    frame : Frame
        What the filter sees (its declared channels only).
    first : bool
        Whether this is the first frame (the compile/warm-up call is made and recorded).
    repeats : int
        Timed calls (>= 1).
    sampler_factory : callable, optional
        Returns a fresh sampler for each call of an adaptive filter.
    check : str, optional
        When given, every output (the warm-up's too) is validated, naming this owner.

    Returns
    -------
    filt : filter object
        The state to continue the sequence with.
    out : ndarray
        The output of the last timed call.
    timing : dict
        ``compile_ms`` (first frame), ``ms_median``, ``ms_min``, ``ms_max``, ``cpu_ms_median``
        (process CPU time, all threads), ``repeats`` and
        ``stage_ms`` (JSON) where the filter declares ``stage_timing``.
    samples : int
        Samples the output is made of (the sampler's count for adaptive filters).
    """
    new_sampler = sampler_factory or (lambda: None)

    def call(instance, sampler):
        out, ms, cpu_ms = timed_call(lambda: instance(frame, sampler=sampler), cuda=backend == "cuda")
        if check is not None:
            check_filter_output(out, frame, owner=check)
        return out, ms, cpu_ms

    stateful = spec.temporal
    timing: dict = {"repeats": repeats}
    if first:
        warm = copy.deepcopy(filt) if stateful else filt
        _, timing["compile_ms"], _ = call(warm, new_sampler())
    times, cpu_times = [], []
    state = filt
    out = sampler = None
    for _ in range(repeats):
        instance = copy.deepcopy(filt) if stateful else filt
        sampler = new_sampler()
        out, ms, cpu_ms = call(instance, sampler)
        times.append(ms)
        cpu_times.append(cpu_ms)
        state = instance
    timing.update(ms_median=float(np.median(times)), ms_min=float(min(times)), ms_max=float(max(times)),
                  cpu_ms_median=float(np.median(cpu_times)))
    stages = getattr(state, "stage_ms", None) if spec.stage_timing else None
    if stages:
        timing["stage_ms"] = json.dumps({k: round(float(v), 4) for k, v in stages.items()})
    if sampler is not None:
        samples = sampler.samples_used
    elif "spp" in frame:
        samples = int(frame["spp"].astype(np.int64).sum())
    else:
        samples = -1
    return state, out, timing, samples


def timed_call(fn: Callable[[], Any], cuda: bool = False) -> tuple[Any, float, float]:
    """Call ``fn()`` once: (its result, wall-clock ms, process CPU ms of every thread).

    Wall time is ``time.perf_counter_ns``, CPU time ``time.process_time_ns``; with ``cuda`` the
    device is synchronised before the clocks stop.
    """
    cpu = time.process_time_ns()
    start = time.perf_counter_ns()
    out = fn()
    if cuda:
        from numba import cuda as device

        device.synchronize()
    ms = (time.perf_counter_ns() - start) / 1e6
    cpu_ms = (time.process_time_ns() - cpu) / 1e6
    return out, ms, cpu_ms


#: the index orders drawn so far, by number of names (:func:`round_order`)
_ORDERS: dict[int, list[list[int]]] = {}


def round_order(names: Sequence[str], round_index: int) -> list[str]:
    """The call order of round ``round_index``: ``names`` as given in round 0, then shuffled.

    Round ``r`` > 0 is a permutation drawn from a generator seeded with (``r``, number of
    names), the same on every run, redrawn until it differs from round ``r - 1``'s and from
    the given order (two names simply swap every round): every name goes through varied
    positions and, above all, follows varied others, so that what one call leaves behind (a
    library's pool threads that keep a core busy after it returns, a cache it filled) is not
    charged to the same name round after round, as a plain rotation would.
    """
    names = list(names)
    n = len(names)
    if n < 3:
        return names if round_index % 2 == 0 else names[::-1]
    orders = _ORDERS.setdefault(n, [list(range(n))])
    while len(orders) <= round_index:
        rng = np.random.default_rng([len(orders), n])
        order = rng.permutation(n).tolist()
        while order == orders[0] or order == orders[-1]:
            order = rng.permutation(n).tolist()
        orders.append(order)
    return [names[k] for k in orders[round_index]]


@dataclass
class Alternation:
    """What :func:`alternate` measured.

    Attributes
    ----------
    ms, cpu_ms : dict
        Name -> wall-clock / process CPU milliseconds of each round's call, in round order.
    order : list of list of str
        The call order of each round.
    first_ms : dict
        Name -> wall-clock milliseconds of the untimed warm-up call (compilation), where made.
    """

    ms: dict = field(default_factory=dict)
    cpu_ms: dict = field(default_factory=dict)
    order: list = field(default_factory=list)
    first_ms: dict = field(default_factory=dict)

    def ratio(self, name: str, other: str, clock: str = "wall") -> np.ndarray:
        """``name``'s time over ``other``'s, round by round (``clock``: ``wall`` or ``cpu``)."""
        times = self.ms if clock == "wall" else self.cpu_ms
        a, b = np.asarray(times[name], np.float64), np.asarray(times[other], np.float64)
        return np.divide(a, b, out=np.full_like(a, np.nan), where=b > 0)


def alternate(calls: Mapping[str, Callable[[], Any]], rounds: int, warm: bool = True,
              cuda: bool = False) -> Alternation:
    """Time each callable once per round, the callables taking turns call by call.

    Parameters
    ----------
    calls : mapping
        Name -> a callable without arguments.
    rounds : int
        Rounds (>= 1); round ``r`` calls them in the order :func:`round_order` (names, r).
    warm : bool
        Call each once, untimed, before the rounds (its wall time kept as ``first_ms``).
    cuda : bool
        Synchronise the CUDA device before each clock stops.
    """
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise ValueError(f"rounds must be an integer >= 1, got {rounds!r}")
    result = Alternation({n: [] for n in calls}, {n: [] for n in calls})
    if warm:
        for name, fn in calls.items():
            result.first_ms[name] = timed_call(fn, cuda)[1]
    for r in range(rounds):
        order = round_order(list(calls), r)
        result.order.append(order)
        for name in order:
            _, ms, cpu_ms = timed_call(calls[name], cuda)
            result.ms[name].append(ms)
            result.cpu_ms[name].append(cpu_ms)
    return result
