"""The pytest plugin of denoise-harness (entry point ``pytest11``): fixtures for plugin authors.

Fixtures
--------
harness_registry
    The registry of installed plugins (session-scoped).
make_frame
    :func:`harness.testing.make_frame`, to build small frames with any channels.
"""

from __future__ import annotations

import pytest

from harness.testing import make_frame as _make_frame
from harness.testing import registry as _registry


@pytest.fixture(scope="session")
def harness_registry():
    """The registry of every installed denoise-harness plugin."""
    return _registry()


@pytest.fixture
def make_frame():
    """Factory of small procedural frames: ``make_frame(height, width, channels, ...)``."""
    return _make_frame
