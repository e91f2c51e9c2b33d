"""The stress battery as conformance checks: one pytest check per (filter, backend, case).

Each :class:`StressCheck` runs its case (:mod:`harness.stress.cases`) through the filter and
fails with the property that did not hold. By default the case runs in a worker process (the
``local`` executor, one per test session, restarted after a crash), so a filter that segfaults
or hangs fails its test instead of ending the test session.
"""

from __future__ import annotations

import atexit

from harness.stress.cases import StressCase, select_cases
from harness.stress.properties import PASSING

#: seconds a case may go without finishing a frame before its worker is stopped
TIMEOUT_S = 300.0

_executor = None


def _worker():
    """The session's worker executor, started on first use and closed at exit."""
    global _executor
    if _executor is None:
        from harness.executors import LocalExecutor

        _executor = LocalExecutor(timeout=TIMEOUT_S)
        atexit.register(_executor.close)
    return _executor


class StressCheck:
    """A check ``check(spec, backend)`` running one stress case.

    Parameters
    ----------
    case : StressCase
    isolate : bool
        Run the case in a worker process (a crash or a hang fails the test) rather than in the
        test process.
    """

    def __init__(self, case: StressCase, isolate: bool = True):
        self.case, self.isolate = case, isolate
        self.__name__ = f"stress:{case.name}"
        self.__doc__ = case.doc

    def __call__(self, spec, backend) -> None:
        from harness.stress.check import run_case
        from harness.stress.units import StressUnit, case_result

        params = dict(spec.params)
        if self.isolate:
            task = StressUnit(spec.name, backend, params, self.case.name)
            (_, outcome), = list(_worker().run([task]))
            result = case_result(outcome, task.label)
        else:
            result = run_case(spec, backend, params, self.case)
        if result.status not in PASSING:
            where = f" at frame {result.frame}" if result.frame >= 0 else ""
            raise AssertionError(f"filter {spec.name!r} [{backend}] stress case {self.case.name!r} "
                                 f"({self.case.doc}): {result.status}{where}: {result.message}")


def stress_checks(spec, which="light", isolate: bool = True) -> list[StressCheck]:
    """The stress checks that apply to the filter ``spec``.

    Parameters
    ----------
    spec : FilterSpec
    which : {"light", "all", None}
        ``light``: every case but the heavy ones (4K, 1,000 frames); ``all``: every case;
        None or False: none.
    isolate : bool
        See :class:`StressCheck`.
    """
    if not which:
        return []
    if which not in ("light", "all"):
        raise ValueError(f"stress must be 'light', 'all' or None, got {which!r}")
    return [StressCheck(c, isolate) for c in select_cases(heavy=which == "all") if c.skip_reason(spec) is None]
