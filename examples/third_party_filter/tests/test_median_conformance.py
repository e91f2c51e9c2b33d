"""How a third party runs the harness's conformance checks on its own filter."""

from harness.testing import parametrize_with_checks


@parametrize_with_checks(filters=["median3"])
def test_median3_conformance(plugin_check):
    plugin_check()
