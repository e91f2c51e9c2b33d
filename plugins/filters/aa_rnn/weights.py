"""The ``aa_rnn`` weights file: save, load and validate.

A weights file is a NumPy ``.npz`` (no pickles) holding one float32 array per convolution,
``conv0`` ... ``conv{L-1}`` (the hidden layers, (32, C_in, 3, 3)) and ``head`` ((3, 32, 3, 3)),
and ``meta``, a JSON string: format name and version, the number of hidden layers, the
training-data hash, the seed, the training configuration and time, the held-out scores and a
SHA-256 of the arrays. Loading checks all of it and raises :class:`WeightsError` with the reason
and the file name.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path

import numpy as np

from .network import N_FEATURES, WIDTH

FORMAT = "aa_rnn-weights"
FORMAT_VERSION = 1
#: the shipped weights, one file per depth; :data:`DEFAULT_LAYERS` is the filter's default
WEIGHTS_DIR = Path(__file__).with_name("weights")
DEFAULT_LAYERS = 2
#: the shipped weights files, checked by the tests: ``file`` is the SHA-256 of the file's bytes
#: (``sha256sum``; the zip entries carry a time stamp, so a retrained file has other bytes),
#: ``arrays`` the :func:`arrays_digest` that retraining with the same seed on the same machine and
#: software reproduces, ``training_data`` the digest of the training sequences it was trained on;
#: ``recipe`` the trainer options (``denoise-bench train aa_rnn -o KEY=VALUE``) and ``seed`` that
#: made it, ``dataset`` the settings of the dataset folder it was trained on (its manifest's
#: ``config``: the paper-scale set of :mod:`.dataset`, Mitsuba scenes included)
SHIPPED = {
    2: {
        "file": "79096422624aba74ad917839b153647e01514b965cb7cb22868eb774bb0d7b4b",
        "arrays": "9d5eb4cea9045098eb38ea8bb22a7163ff0db10aefe891af7540522b65e4155d",
        "training_data": "a2ef0167db6889c8c47bfc4811fb7b14c5df326cb894f3f85b3092e22eb8bcc2",
        "seed": 0,
        "recipe": {"data": "datasets/cache/aa_rnn-data", "train_sequences": 1140, "epochs": 12, "val_sequences": 64,
                   "eval_every": 1},
        "dataset": {"sequences": 1900, "frames": 7, "size": 64, "seed": 0, "reference_spp": 64,
                    "mitsuba_share": 0.15, "mitsuba": ["classroom", "living-room", "sponza"]},
    },
}


class WeightsError(ValueError):
    """A weights file is missing, corrupted or incompatible with this version of the filter."""


def shipped_weights(layers: int) -> Path:
    """Path of the shipped weights of a network with ``layers`` hidden layers."""
    return WEIGHTS_DIR / f"aa_rnn_l{int(layers)}.npz"


def layer_shapes(layers: int) -> dict[str, tuple]:
    """The array names and shapes of a network with ``layers`` hidden layers."""
    shapes = {"conv0": (WIDTH, N_FEATURES, 3, 3)}
    shapes.update({f"conv{k}": (WIDTH, WIDTH, 3, 3) for k in range(1, layers)})
    shapes["head"] = (3, WIDTH, 3, 3)
    return shapes


def arrays_digest(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 over the names, shapes and float32 bytes of the arrays, in name order."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name], dtype=np.float32)
        h.update(name.encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def model_arrays(model) -> dict[str, np.ndarray]:
    """The weights of an :class:`.network.AARNN` as named float32 arrays (copies: a view of a CPU
    tensor would follow the training that goes on changing it)."""
    arrays = {f"conv{k}": conv.weight.detach().cpu().numpy() for k, conv in enumerate(model.body)}
    arrays["head"] = model.head.weight.detach().cpu().numpy()
    return {k: np.array(v, dtype=np.float32, order="C", copy=True) for k, v in arrays.items()}


def load_into(model, arrays: dict[str, np.ndarray]) -> None:
    """Copy named arrays into an :class:`.network.AARNN` of the same depth."""
    import torch

    with torch.no_grad():
        for k, conv in enumerate(model.body):
            conv.weight.copy_(torch.from_numpy(arrays[f"conv{k}"]))
        model.head.weight.copy_(torch.from_numpy(arrays["head"]))


def save_weights(arrays: dict[str, np.ndarray], meta: dict, path: str | Path) -> Path:
    """Write the arrays with their metadata and checksum to ``path`` (``.npz``); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    layers = len(arrays) - 1
    expected = layer_shapes(layers)
    if set(arrays) != set(expected) or any(arrays[k].shape != s for k, s in expected.items()):
        got = {k: tuple(v.shape) for k, v in arrays.items()}
        raise WeightsError(f"aa_rnn weights: arrays {got} do not form a network (expected {expected})")
    meta = dict(meta)
    meta.update(format=FORMAT, format_version=FORMAT_VERSION, layers=layers, width=WIDTH, features=N_FEATURES,
                arrays_sha256=arrays_digest(arrays))
    with open(path, "wb") as fh:
        np.savez(fh, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)
    return path


def load_weights(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Read and validate a weights file; returns ``(arrays, meta)``.

    Raises
    ------
    WeightsError
        When the file is missing, unreadable or truncated, fails its checksum, has another format
        version, arrays that do not form a network, or non-finite values.
    """
    path = Path(path)
    where = f"aa_rnn weights {path}"
    if not path.is_file():
        raise WeightsError(f"{where}: file not found (train one with `denoise-bench train aa_rnn`)")
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = {name: np.array(data[name]) for name in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise WeightsError(f"{where}: corrupted or not an .npz file ({type(exc).__name__}: {exc})") from None
    try:
        meta = json.loads(str(stored.pop("meta")))
    except (KeyError, json.JSONDecodeError) as exc:
        raise WeightsError(f"{where}: missing or corrupted metadata ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise WeightsError(f"{where}: not an aa_rnn weights file")
    if meta.get("format_version") != FORMAT_VERSION:
        raise WeightsError(f"{where}: format version {meta.get('format_version')!r} is not {FORMAT_VERSION}; "
                           f"retrain with `denoise-bench train aa_rnn`")
    layers = meta.get("layers")
    expected = layer_shapes(layers) if isinstance(layers, int) and layers >= 1 else {}
    if not expected or set(stored) != set(expected) or any(stored[k].shape != s for k, s in expected.items()):
        got = {k: tuple(v.shape) for k, v in stored.items()}
        raise WeightsError(f"{where}: arrays {got} do not match {layers!r} hidden layers")
    arrays = {k: v.astype(np.float32) for k, v in stored.items()}
    if arrays_digest(arrays) != meta.get("arrays_sha256"):
        raise WeightsError(f"{where}: checksum mismatch; the weights were altered or corrupted")
    bad = sorted(k for k, v in arrays.items() if not np.isfinite(v).all())
    if bad:
        raise WeightsError(f"{where}: non-finite values in {bad}")
    return arrays, meta
