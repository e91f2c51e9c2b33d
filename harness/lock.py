"""A lock on a run's output folder, so that two runs never write into one folder at once."""

from __future__ import annotations

import fcntl
import json
import os
import platform
import sys
import time
from pathlib import Path

LOCK_NAME = ".lock"
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
    """The output folder, created; a one-line ``ValueError`` when it is a file or not writable."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file, not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise ValueError(f"--out {out} is not writable ({exc.strerror or exc})") from None
    return out
