"""A content-addressed on-disk store of renders and references.

Keys are SHA-256 digests of everything that determines the stored arrays (scene content hash,
renderer name, version and settings, frame, spp, seed, channels, resolution), so a changed
input misses instead of returning stale data. Every write goes to a temporary file in the same
folder and is renamed into place, so an interrupted run never leaves a half-written entry; an
entry that cannot be read anyway (a truncated or altered file) is a miss: it is named in a
warning, removed (a directory in its place too) and rendered again. :meth:`Cache.check` tells
before any work whether the cache folder can be used. Temporary files left by killed processes are removed by
:func:`clean_temporaries`. Files are written readable by others (mode 0644 under the usual umask).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

DEFAULT_DIR = Path("datasets") / "cache"
CACHE_ENV = "DENOISE_HARNESS_CACHE"
#: suffix of the temporary files of atomic writes
TEMP_SUFFIX = ".tmp"
#: when this process started (temporary files older than that, by a margin, are abandoned)
PROCESS_START = time.time()
#: margin for writers started a little before this process (seconds)
TEMP_GRACE_S = 300.0


def _file_mode() -> int:
    """0666 less the process umask (read from /proc where possible: ``os.umask`` would race)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return 0o666 & ~int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    return 0o644


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
    """Write ``data`` to ``path`` through a temporary file and an atomic rename (mode 0644)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=TEMP_SUFFIX, dir=path.parent)
    try:
        os.fchmod(fd, _file_mode())
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def clean_temporaries(root: str | Path, older_than: float | None = None) -> int:
    """Remove temporary files of atomic writes under ``root`` that were abandoned.

    Parameters
    ----------
    root : path
    older_than : float, optional
        Modification-time cutoff (seconds since the epoch); by default the start of this
        process less :data:`TEMP_GRACE_S`, so that a concurrent writer's file is left alone.

    Returns
    -------
    int
        The number of files removed.
    """
    root = Path(root)
    cutoff = (PROCESS_START - TEMP_GRACE_S) if older_than is None else older_than
    removed = 0
    if not root.is_dir():
        return 0
    for path in root.rglob(f".*{TEMP_SUFFIX}"):
        try:
            if path.is_file() and path.stat().st_mtime < cutoff:
                path.unlink()
                removed += 1
        except OSError:
            continue
    return removed


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

    def check(self) -> Cache:
        """The cache, checked usable before any work: a one-line ``ValueError`` when its folder is a
        file or cannot be written (a file is made and removed there; folders made for the check are
        removed again)."""
        if not self.enabled:
            return self
        root = self.root
        made = [p for p in (root, *root.absolute().parents) if not p.exists()]
        blocker = next((p for p in (root, *root.absolute().parents) if p.exists()), None)
        if blocker is not None and not blocker.is_dir():
            raise ValueError(f"cache folder {root}: {blocker} is a file, not a folder (--cache-dir or ${CACHE_ENV})")
        try:
            root.mkdir(parents=True, exist_ok=True)
            fd, probe = tempfile.mkstemp(prefix=".write-test.", suffix=TEMP_SUFFIX, dir=root)
            os.close(fd)
            os.unlink(probe)
        except OSError as exc:
            raise ValueError(f"cache folder {root} is not writable ({exc.strerror or exc}); choose another with "
                             "--cache-dir, or run with --no-cache") from None
        finally:
            for folder in made:  # deepest first
                try:
                    folder.rmdir()
                except OSError:
                    break
        return self

    def path(self, kind: str, key: str) -> Path:
        return self.root / kind / key[:2] / f"{key}.npz"

    def load(self, kind: str, key: str) -> dict[str, np.ndarray] | None:
        """The arrays stored under ``(kind, key)``, or None.

        An entry that cannot be read (truncated, altered, not an ``.npz``) counts as a miss: a
        warning names the file and the error, and the file is removed so it is rendered again.
        """
        if not self.enabled:
            return None
        path = self.path(kind, key)
        if path.exists():
            try:
                with np.load(path, allow_pickle=False) as data:
                    arrays = {name: data[name] for name in data.files}
                self.hits[kind] = self.hits.get(kind, 0) + 1
                return arrays
            except Exception as exc:  # any unreadable file: zipfile.BadZipFile, OSError, ValueError, ...
                warnings.warn(f"cache entry {path} is unreadable ({type(exc).__name__}: {exc}); "
                              "removed, rendering it again", stacklevel=2)
                _remove(path)
        self.misses[kind] = self.misses.get(kind, 0) + 1
        return None

    def store(self, kind: str, key: str, arrays: dict[str, np.ndarray]) -> None:
        """Store ``arrays`` atomically under ``(kind, key)``."""
        if not self.enabled:
            return
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        path = self.path(kind, key)
        if path.is_dir() and not path.is_symlink():
            _remove(path)
        atomic_write_bytes(path, buf.getvalue())

    def discard(self, kind: str, key: str) -> None:
        _remove(self.path(kind, key))


def _remove(path: Path) -> None:
    """Remove a cache entry: its file, or a directory that took its place."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)
