"""The pytest plugin of denoise-harness (entry point ``pytest11``): fixtures for plugin authors.

Fixtures
--------
harness_registry
    The registry of installed plugins (session-scoped).
make_frame
    :func:`harness.testing.make_frame`, to build small frames with any channels.

Markers
-------
slow
    Tests of the full tier only: :func:`harness.testing.parametrize_with_checks` marks all but
    one stress case per group of each filter with it, so ``pytest -m "not slow"`` is a fast
    tier that still runs every check and every group of the battery.
"""

from __future__ import annotations

import pytest

from harness.testing import make_frame as _make_frame
from harness.testing import registry as _registry


def pytest_configure(config):
    """Register the ``slow`` marker (the full tier's tests)."""
    config.addinivalue_line("markers", "slow: costly tests, run in the full tier only (deselect with -m 'not slow')")


@pytest.fixture(scope="session")
def harness_registry():
    """The registry of every installed denoise-harness plugin."""
    return _registry()


@pytest.fixture
def make_frame():
    """Factory of small procedural frames: ``make_frame(height, width, channels, ...)``."""
    return _make_frame
