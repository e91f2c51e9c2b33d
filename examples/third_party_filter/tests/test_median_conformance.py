"""How a third party runs the harness's conformance checks on its own filter.

One test per check, plus one per stress case that applies (``...-stress:guide-all-background``,
``...-stress:shape-1x1``, ...), each run in a worker process so a crash fails only its test.
``stress="all"`` adds the heavy 4K and 1,000-frame cases; a case the filter cannot pass is
declared in its ``FilterSpec.stress_exempt`` with the measured reason.
"""

from harness.testing import parametrize_with_checks


@parametrize_with_checks(filters=["median3"])
def test_median3_conformance(plugin_check):
    plugin_check()
