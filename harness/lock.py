"""A run's output folder: checked before use, locked so that two runs never write into it at once.

An output folder is written only where it is new, empty, or already a denoise-bench output
folder (it holds the :data:`LOCK_NAME` file every run leaves, or a run's ``manifest.json``): a run
prunes and replaces files it owns there (``jobs/``, ``results.parquet``, ``report-frames/``), so
it never starts in a folder of other files. :func:`output_folder` leaves a refused run's folder
as it found it (no empty folder with a lock file).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import platform
import sys
import time
from collections.abc import Iterator
from pathlib import Path

LOCK_NAME = ".lock"
#: files whose presence marks a folder as a denoise-bench output folder (a run or a stress run)
OUTPUT_MARKERS = (LOCK_NAME, "manifest.json")
#: folders this process holds: resolved path -> [fd, holders]
_HELD: dict[Path, list] = {}


class FolderLocked(RuntimeError):
    """Another process holds the folder's lock."""


class FolderLock:
    """An exclusive ``flock`` on ``folder/.lock``, released on :meth:`release` or process exit.

    The lock file records who holds it (pid, host, command, start time), so that a second run
    can say whom it is waiting for. A lock left by a killed process is free (the kernel drops
    ``flock`` locks with their process). The lock is re-entrant within a process.

    Parameters
    ----------
    folder : path
    """

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self._held = False

    def acquire(self) -> FolderLock:
        """Take the lock; :class:`FolderLocked` names the holder when another process has it."""
        self.folder.mkdir(parents=True, exist_ok=True)
        key = self.folder.resolve()
        if key in _HELD:
            _HELD[key][1] += 1
            self._held = True
            return self
        path = self.folder / LOCK_NAME
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _describe(os.read(fd, 4096))
            os.close(fd)
            raise FolderLocked(f"{self.folder} is in use by another run ({holder}); wait for it or choose "
                               "another --out") from None
        os.ftruncate(fd, 0)
        info = {"pid": os.getpid(), "host": platform.node(), "command": " ".join(Path(a).name if i == 0 else a
                                                                                  for i, a in enumerate(sys.argv)),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S")}
        os.write(fd, json.dumps(info).encode())
        _HELD[key] = [fd, 1]
        self._held = True
        return self

    def release(self) -> None:
        if not self._held:
            return
        self._held = False
        key = self.folder.resolve()
        entry = _HELD[key]
        entry[1] -= 1
        if entry[1] == 0:
            del _HELD[key]
            os.ftruncate(entry[0], 0)
            fcntl.flock(entry[0], fcntl.LOCK_UN)
            os.close(entry[0])

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def _describe(raw: bytes) -> str:
    try:
        info = json.loads(raw.decode())
        return f"pid {info['pid']} on {info['host']}, '{info['command']}', started {info['started']}"
    except (ValueError, KeyError, UnicodeDecodeError):
        return "holder unknown"


def check_out_dir(out_dir: str | Path) -> Path:
    """The output folder, created; a one-line ``ValueError`` when it cannot be one.

    Refused: an empty name (it would be the current directory), a file, a folder that is not
    writable, and a folder that holds files but is no denoise-bench output folder (no
    :data:`OUTPUT_MARKERS` file).
    """
    if not str(out_dir).strip():
        raise ValueError("--out must name a folder, got ''")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder")
    if out.is_dir() and not is_output_folder(out):
        raise ValueError(f"--out {out} holds other files and is no denoise-bench output folder (it has no "
                         f"{' or '.join(OUTPUT_MARKERS)}); choose a new or an empty folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ValueError(f"--out {out} is not writable ({exc.strerror or exc})") from None
    return out


def is_output_folder(folder: str | Path) -> bool:
    """True for an empty folder or one holding a :data:`OUTPUT_MARKERS` file (False where unreadable)."""
    folder = Path(folder)
    try:
        names = {p.name for p in folder.iterdir()}
    except OSError:
        return False
    return not names or bool(names & set(OUTPUT_MARKERS))


@contextlib.contextmanager
def output_folder(out_dir: str | Path) -> Iterator[Path]:
    """:func:`check_out_dir` and :class:`FolderLock` around the body.

    A body that raises before anything but the lock was written leaves no trace: the lock file
    and the folders made for it are removed (never another process's lock: a folder locked by
    another run raises :class:`FolderLocked` before the body and is left alone).
    """
    out = Path(out_dir)
    made = [p for p in (out, *out.parents) if not p.exists()]
    try:
        lock = FolderLock(check_out_dir(out))
    except ValueError:
        _remove_unused(out, made)
        raise
    lock.acquire()
    try:
        yield out
    except BaseException:
        lock.release()
        _remove_unused(out, made)
        raise
    lock.release()


def _remove_unused(out: Path, made: list) -> None:
    """Remove the lock file of ``out`` if it is all the folder holds, then the empty folders in ``made``."""
    try:
        if out.is_dir() and {p.name for p in out.iterdir()} == {LOCK_NAME}:
            (out / LOCK_NAME).unlink()
        for folder in made:  # deepest first
            if folder.is_dir():
                folder.rmdir()
    except OSError:
        return
