"""Short, one-line descriptions of exceptions for result rows and plugin listings."""

from __future__ import annotations

import traceback
from pathlib import Path


def short_error(exc: BaseException, limit: int = 300) -> str:
    """``Type: message (file:line)`` of the innermost frame, at most ``limit`` characters."""
    tb = traceback.extract_tb(exc.__traceback__)
    where = f" ({Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
    text = f"{type(exc).__name__}: {exc}".replace("\n", " ")
    return (text[: limit - len(where)] + where) if len(text) + len(where) > limit else text + where


def filter_error(exc: BaseException) -> str:
    """:func:`short_error`, with ``sys.exit`` from a plugin named as such."""
    if isinstance(exc, SystemExit):
        return f"SystemExit: the filter called sys.exit({exc.code!r})"
    return short_error(exc)
