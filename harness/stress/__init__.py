"""Numerical stress testing: the battery, its properties, fuzzing with shrinking, and the stress run.

``denoise-bench stress`` runs every selected filter through the battery of
:mod:`harness.stress.cases` (extreme colour, degenerate guides, odd shapes up to 4K, long and
cut sequences, frames repaired by the non-finite policy), checking the properties of
:mod:`harness.stress.properties` on every call; ``--fuzz N`` searches generated frames with
Hypothesis and shrinks a failure to a minimal reproducer (:mod:`harness.stress.fuzz`,
:mod:`harness.stress.reproducer`); ``--replay FILE`` runs a reproducer again. Cases run as
executor tasks (:mod:`harness.stress.units`), so a crash is a row; :mod:`harness.stress.run`
stores the table (:mod:`harness.stress.table`) and a manifest. The same cases are pytest
checks through :func:`harness.testing.parametrize_with_checks`.
"""

from harness.stress.cases import CASES, GROUPS, Sequence, StressCase, exemption, select_cases
from harness.stress.check import CaseResult, run_case, run_sequence
from harness.stress.reproducer import load_reproducer, save_reproducer
from harness.stress.run import StressOutcome, Target, make_targets, read_stress, run_stress

__all__ = [
    "CASES",
    "GROUPS",
    "CaseResult",
    "Sequence",
    "StressCase",
    "StressOutcome",
    "Target",
    "exemption",
    "load_reproducer",
    "make_targets",
    "read_stress",
    "run_case",
    "run_sequence",
    "run_stress",
    "save_reproducer",
    "select_cases",
]
