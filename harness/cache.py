"""A content-addressed on-disk store of renders and references.

Keys are SHA-256 digests of everything that determines the stored arrays (scene content hash,
renderer name, version and settings, frame, spp, seed, channels, resolution), so a changed
input misses instead of returning stale data. Every write goes to a temporary file in the same
folder and is renamed into place, so an interrupted run never leaves a half-written entry.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import tempfile
from pathlib import Path

import numpy as np

DEFAULT_DIR = Path("datasets") / "cache"
CACHE_ENV = "DENOISE_HARNESS_CACHE"


def default_cache_dir() -> Path:
    """``$DENOISE_HARNESS_CACHE`` or ``datasets/cache`` under the current directory."""
    return Path(os.environ.get(CACHE_ENV) or DEFAULT_DIR)


def plain(value):
    """``value`` with sets, tuples, mappings and NumPy scalars turned into JSON-able types."""
    if isinstance(value, dict) or hasattr(value, "items"):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (set, frozenset)):
        return sorted(plain(v) for v in value)
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def make_key(**parts) -> str:
    """SHA-256 hex digest of the JSON encoding of ``parts`` (sorted keys; sets sorted)."""
    payload = json.dumps(plain(parts), sort_keys=True, default=str)
    return hashlib.sha256(payload.encode()).hexdigest()


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and an atomic rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def array_hash(array: np.ndarray) -> str:
    """SHA-256 of an array's dtype, shape and bytes."""
    h = hashlib.sha256(f"{array.dtype.str}{array.shape}".encode())
    h.update(np.ascontiguousarray(array).tobytes())
    return h.hexdigest()


class Cache:
    """Arrays stored by kind and key under ``root``.

    Parameters
    ----------
    root : path
    enabled : bool
        When False, nothing is read or written (``--no-cache``).

    Attributes
    ----------
    hits, misses : dict
        Counts per kind, for the run summary.
    """

    def __init__(self, root: str | Path | None = None, enabled: bool = True):
        self.root = Path(root) if root is not None else default_cache_dir()
        self.enabled = enabled
        self.hits: dict[str, int] = {}
        self.misses: dict[str, int] = {}

    def path(self, kind: str, key: str) -> Path:
        return self.root / kind / key[:2] / f"{key}.npz"

    def load(self, kind: str, key: str) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``(kind, key)``, or None (a corrupt entry counts as a miss)."""
        if not self.enabled:
            return None
        path = self.path(kind, key)
        if path.exists():
            try:
                with np.load(path, allow_pickle=False) as data:
                    arrays = {name: data[name] for name in data.files}
                self.hits[kind] = self.hits.get(kind, 0) + 1
                return arrays
            except (OSError, ValueError, EOFError):
                path.unlink(missing_ok=True)
        self.misses[kind] = self.misses.get(kind, 0) + 1
        return None

    def store(self, kind: str, key: str, arrays: dict[str, np.ndarray]) -> None:
        """Store ``arrays`` atomically under ``(kind, key)``."""
        if not self.enabled:
            return
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        atomic_write_bytes(self.path(kind, key), buf.getvalue())

    def discard(self, kind: str, key: str) -> None:
        self.path(kind, key).unlink(missing_ok=True)
