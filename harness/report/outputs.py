"""The filter outputs a report shows, stored beside a run's results (``DIR/report-frames/``).

With ``run --report`` each job of the first seed keeps its outputs of three frames of its
sequence (the first, the middle and the last: the last has the longest history), and the
group stores the noisy input and the reference of the same frames. Arrays are float16 ``.npy``
files (a 1280x720 image is 5.5 MB): ``report-frames/<task>/<scene>/<name>-f<frame>.npy`` where
``name`` is the job's configuration (:func:`output_name`), ``input-spp<N>`` or ``reference``.
A run without ``--resume`` removes the folder first, so it never shows another run's images.
"""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np

from harness.cache import atomic_write_bytes, make_key


def kept_frames(count: int) -> list[int]:
    """The frame indices a report keeps of a sequence of ``count`` frames."""
    return sorted({0, (count - 1) // 2, count - 1})


def safe_name(text: str) -> str:
    """A file-name-safe version of an entry label."""
    return re.sub(r"[^A-Za-z0-9._=-]+", "_", text).strip("_") or "entry"


def output_name(job) -> str:
    """The stored name of a job's (or a row's) outputs: filter, preset, backend, spp and (hashed) parameters."""
    preset = f"[{job.preset}]" if job.preset else ""
    params = make_key(params=job.params)[:8]
    return safe_name(f"{job.filter}{preset}-{job.backend}-spp{job.spp}-{params}")


#: the folder of a run that holds the kept frames
FOLDER = "report-frames"


def folder(out_dir: str | Path, task: str, scene: str) -> Path:
    """Where the kept frames of one scene of one task are stored."""
    return Path(out_dir) / FOLDER / safe_name(task) / safe_name(scene)


def save(out_dir, task: str, scene: str, name: str, frame: int, image: np.ndarray) -> Path:
    """Store one image (float16) atomically; returns its path."""
    path = folder(out_dir, task, scene) / f"{name}-f{frame}.npy"
    buf = io.BytesIO()
    np.save(buf, np.asarray(image, np.float16), allow_pickle=False)
    atomic_write_bytes(path, buf.getvalue())
    return path


def load(out_dir, task: str, scene: str, name: str, frame: int) -> np.ndarray | None:
    """A stored image as float32, or None."""
    path = folder(out_dir, task, scene) / f"{name}-f{frame}.npy"
    if not path.exists():
        return None
    return np.load(path, allow_pickle=False).astype(np.float32)


__all__ = ["FOLDER", "folder", "kept_frames", "load", "output_name", "safe_name", "save"]
