"""Where Numba keeps its compiled-function cache: a folder keyed by the source of every plugin.

Numba's on-disk cache (``cache=True``) checks only the timestamp of the file that defines a
function, not of the files whose functions it inlined or called. After an edit to a helper
module, a stale cached kernel can run with the old code, or crash. The harness therefore points
Numba at ``<cache home>/denoise-harness/numba/<digest>``, where the digest covers the source of
the ``harness`` and ``plugins`` packages: any edit to them starts a fresh cache. A
``NUMBA_CACHE_DIR`` set by the user is left alone. Third-party plugins keep Numba's default
(their own ``__pycache__``).
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path


def source_digest(*packages: Path) -> str:
    """SHA-256 (first 16 hex digits) over the relative paths and bytes of every ``.py`` file."""
    h = hashlib.sha256()
    for root in packages:
        for path in sorted(root.rglob("*.py")):
            h.update(path.relative_to(root.parent).as_posix().encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def configure_numba_cache() -> Path | None:
    """Point Numba's cache at a folder keyed by the harness's and built-in plugins' source.

    Returns the folder, or None when the user set ``NUMBA_CACHE_DIR`` themselves.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    here = Path(__file__).resolve().parent
    packages = [here]
    plugins = here.parent / "plugins"
    if plugins.is_dir():
        packages.append(plugins)
    home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    folder = home / "denoise-harness" / "numba" / source_digest(*packages)
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    if "numba" in sys.modules:  # numba read its configuration already
        sys.modules["numba"].config.CACHE_DIR = str(folder)
    return folder
