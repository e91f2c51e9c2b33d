"""Reproducer files: the frames of a failure and how to replay it, in one ``.npz``.

Layout: each frame's channels and metadata under ``"<t>:<channel>"`` and ``"<t>:__meta__"``
(:meth:`harness.Frame.to_arrays`, bit for bit), and ``"__stress__"``: UTF-8 JSON with the
filter, backend, parameters, the frames before which ``reset()`` is called, the properties
checked, what failed, and the command that replays it (``denoise-bench stress --replay FILE``).
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np

from harness.buffers import Frame
from harness.cache import atomic_write_bytes

INFO_KEY = "__stress__"


def replay_command(path: str | Path) -> str:
    """The command line that replays the reproducer at ``path``."""
    return f"denoise-bench stress --replay {path}"


def save_reproducer(path: str | Path, frames: list[Frame], info: dict) -> Path:
    """Write ``frames`` and ``info`` (JSON-able; ``command`` is added) to ``path`` atomically."""
    path = Path(path)
    arrays = {}
    for t, frame in enumerate(frames):
        for name, array in frame.to_arrays().items():
            arrays[f"{t}:{name}"] = array
    info = {**info, "frames": len(frames), "command": replay_command(path)}
    arrays[INFO_KEY] = np.frombuffer(json.dumps(info, sort_keys=True).encode(), np.uint8)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())
    return path


def load_reproducer(path: str | Path) -> tuple[list[Frame], dict]:
    """The frames and info of a reproducer file.

    Raises
    ------
    FileNotFoundError
        No such file.
    ValueError
        The file is not a stress reproducer (the message names it).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no reproducer file {path}")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a stress reproducer: not an .npz archive")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except Exception as exc:
        raise ValueError(f"{path} is not a stress reproducer (.npz): {type(exc).__name__}: {exc}") from None
    if INFO_KEY not in arrays:
        raise ValueError(f"{path} is not a stress reproducer: it has no {INFO_KEY!r} entry")
    info = json.loads(bytes(arrays.pop(INFO_KEY)).decode())
    frames = []
    for t in range(int(info.get("frames", 0))):
        prefix = f"{t}:"
        frames.append(Frame.from_arrays({k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)},
                                        owner=f"reproducer {path.name}"))
    if not frames:
        raise ValueError(f"{path} is not a stress reproducer: it holds no frames")
    return frames, info
