"""A stress case as an executor work unit: it runs in the worker, so a crash or a hang is one row.

The filter's first call on a small ordinary frame (its compilation) is the work unit's ``prepare``
step, which the ``local`` executor runs before the case under its own, longer limit: a cold
compile cache on a loaded machine never counts against the case's ``--timeout``. Python warnings
a case raises (NumPy overflow on extreme input, say) go into the row's ``notes`` instead of the
terminal.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

from harness.executors.base import Outcome, WorkerContext, WorkUnit
from harness.stress.cases import CASES, Sequence
from harness.stress.check import CaseResult, run_case, run_sequence
from harness.stress.frames import scene_frame

#: (filter, backend, params) already warmed up in this process
_WARM: set = set()


@dataclass
class StressUnit(WorkUnit):
    """Run one filter over one case of the battery, or over frames it carries (fuzzing, replay).

    Attributes
    ----------
    filter, backend : str
    params : dict
        Filter parameters (checked by the caller).
    case : str
        A battery case (:data:`harness.stress.cases.CASES`) or, with ``frames``, a label.
    frames : list of Frame, optional
        Explicit frames (small: fuzzing examples and reproducers).
    resets : tuple of int
        With ``frames``: indices before which ``reset()`` is called.
    flags : dict
        With ``frames``: the properties that hold (``flat``, ``energy``, ``fresh``, ``rejects``).
    """

    filter: str
    backend: str
    params: dict
    case: str
    frames: list | None = None
    resets: tuple = ()
    flags: dict = field(default_factory=dict)

    @property
    def label(self) -> str:
        return f"{self.filter}/{self.backend} stress {self.case}"

    def prepare(self, context: WorkerContext) -> None:
        """Compile: one call of the filter on a small ordinary frame (:func:`warm_up`), outside the case's timeout."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            warm_up(context.registry.get("filter", self.filter), self.backend, self.params)

    def run(self, context: WorkerContext, shared) -> CaseResult:
        spec = context.registry.get("filter", self.filter)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            warm_up(spec, self.backend, self.params)
            del caught[:]  # the warm-up's warnings are not the case's
            if self.frames is None:
                result = run_case(spec, self.backend, self.params, CASES[self.case], progress=context.progress)
            else:
                sequence = Sequence.of(self.frames, self.resets)
                result = run_sequence(spec, self.backend, self.params, sequence, progress=context.progress,
                                      **self.flags)
        result.notes = "; ".join(filter(None, [result.notes, warning_note(caught)]))
        return result


def warm_up(spec, backend: str, params: dict) -> None:
    """Call a fresh filter once per process on a small ordinary frame, so case times exclude compilation.

    Errors are ignored here: the case that follows meets them and reports them.
    """
    key = (spec.name, spec.version, backend, repr(sorted(params.items())))
    if key in _WARM:
        return
    _WARM.add(key)
    channels = spec.requires | spec.optional
    try:
        filt = spec.factory(backend=backend, **params)
        filt.reset()
        for t in range(2 if spec.temporal else 1):
            filt(scene_frame(16, 12, channels, seed=t, index=t), sampler=None)
    except (Exception, SystemExit):
        pass


def warning_note(caught: list) -> str:
    """The Python warnings a case raised (extreme input makes NumPy warn), kept as a note, not printed."""
    if not caught:
        return ""
    seen = dict.fromkeys(f"{w.category.__name__}: {w.message} ({w.filename.rsplit('/', 1)[-1]}:{w.lineno})"
                         for w in caught)
    shown = "; ".join(list(seen)[:3]) + (f"; and {len(seen) - 3} more" if len(seen) > 3 else "")
    return f"{len(caught)} warning(s): {shown}"


def case_result(outcome: Outcome, label: str) -> CaseResult:
    """The case result of an executor outcome; a worker's death or a hang becomes ``crash``/``timeout``."""
    if outcome.ok:
        return outcome.value
    error = outcome.error.removeprefix(f"{label}: ")
    if error.startswith("timed out: no progress"):
        status = "timeout"
    elif "the worker process" in error:
        status = "crash"
    else:
        status = "error"
    return CaseResult(status=status, message=error, frame=outcome.progress, calls=outcome.progress)
