"""Every registered plugin passes the harness's conformance checks."""

from harness.testing import parametrize_with_checks


@parametrize_with_checks()
def test_plugin_conformance(plugin_check):
    plugin_check()
