"""The LBF weights file: save, load and validate.

A weights file is a NumPy ``.npz`` (no pickles) holding the arrays ``w1`` (10, 36), ``b1`` (10,),
``w2`` (6, 10), ``b2`` (6,), ``mean`` and ``std`` (36,) (the z-normalisation statistics of the
training features) and ``meta``, a JSON string with the format name and version, the feature
list, the layer shapes, the filter radius used in training, the training-data hash, the seed,
the held-out scores and a SHA-256 of the arrays. Loading checks all of it and raises
:class:`WeightsError` with the reason and the file name.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import kernels as K
from .features import FEATURE_NAMES

FORMAT = "lbf-weights"
FORMAT_VERSION = 1
ARRAYS = ("w1", "b1", "w2", "b2", "mean", "std")
OUTPUT_NAMES = ("spatial", "color", "position", "normal", "albedo", "visibility")
SHAPES = {
    "w1": (K.N_HIDDEN, K.N_FEATURES),
    "b1": (K.N_HIDDEN,),
    "w2": (K.N_OUT, K.N_HIDDEN),
    "b2": (K.N_OUT,),
    "mean": (K.N_FEATURES,),
    "std": (K.N_FEATURES,),
}
#: the shipped weights (v2: procedural and real training data; the file format is FORMAT_VERSION 1)
DEFAULT_WEIGHTS = Path(__file__).with_name("weights") / "lbf_v2.npz"
#: features whose training deviation is below this are not scaled (e.g. 1/spp at constant spp)
STD_FLOOR = 1e-6


class WeightsError(ValueError):
    """A weights file is missing, corrupted or incompatible with this version of the filter."""


@dataclass
class LBFWeights:
    """Network weights and feature statistics of LBF.

    Attributes
    ----------
    w1, b1, w2, b2 : ndarray float32
        The layers (see :data:`SHAPES`).
    mean, std : ndarray (36,) float32
        Training-set mean and standard deviation of each feature.
    meta : dict
        Provenance: ``training_data_hash``, ``seed``, ``radius``, ``heldout_relmse``, ...
    """

    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        for name in ARRAYS:
            setattr(self, name, np.ascontiguousarray(getattr(self, name), dtype=np.float32))

    @property
    def inv_std(self) -> np.ndarray:
        """1 / std, with features of (near) zero training deviation left unscaled."""
        inv = np.where(self.std > STD_FLOOR, 1.0 / np.maximum(self.std, STD_FLOOR), 1.0)
        return inv.astype(np.float32)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: getattr(self, name) for name in ARRAYS}


def arrays_digest(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 over the names, shapes and float32 bytes of the weight arrays."""
    h = hashlib.sha256()
    for name in ARRAYS:
        a = np.ascontiguousarray(arrays[name], dtype=np.float32)
        h.update(name.encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_weights(model: LBFWeights, path: str | Path) -> Path:
    """Write ``model`` to ``path`` (``.npz``) with its metadata and checksum; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = model.arrays()
    for name, shape in SHAPES.items():
        if arrays[name].shape != shape:
            got = arrays[name].shape
            raise WeightsError(f"lbf weights: array {name!r} has shape {got}, expected {shape}")
    meta = dict(model.meta)
    meta.update(
        format=FORMAT,
        format_version=FORMAT_VERSION,
        feature_names=list(FEATURE_NAMES),
        outputs=list(OUTPUT_NAMES),
        layer_shapes={k: list(v) for k, v in SHAPES.items()},
        activations=["sigmoid", "softplus"],
        arrays_sha256=arrays_digest(arrays),
    )
    with open(path, "wb") as fh:
        np.savez(fh, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)
    return path


def load_weights(path: str | Path | None = None) -> LBFWeights:
    """Read and validate a weights file.

    Parameters
    ----------
    path : str or Path, optional
        The ``.npz`` file; None loads the shipped weights.

    Returns
    -------
    LBFWeights

    Raises
    ------
    WeightsError
        When the file is missing, unreadable or truncated, fails its checksum, has another
        format version, another feature list or other layer shapes, or holds non-finite values.
    """
    path = Path(path) if path is not None else DEFAULT_WEIGHTS
    where = f"lbf weights {path}"
    if not path.is_file():
        raise WeightsError(f"{where}: file not found (train one with `denoise-bench train lbf`)")
    try:
        with np.load(path, allow_pickle=False) as data:
            stored = {name: np.array(data[name]) for name in data.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        reason = f"{type(exc).__name__}: {exc}"
        raise WeightsError(f"{where}: corrupted or not an .npz file ({reason})") from None
    if "meta" not in stored:
        raise WeightsError(f"{where}: no 'meta' entry; not an LBF weights file")
    try:
        meta = json.loads(str(stored["meta"]))
    except json.JSONDecodeError as exc:
        raise WeightsError(f"{where}: corrupted metadata ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        found = meta.get("format") if isinstance(meta, dict) else meta
        raise WeightsError(f"{where}: not an LBF weights file (format {found!r})")
    version = meta.get("format_version")
    if version != FORMAT_VERSION:
        raise WeightsError(
            f"{where}: format version {version!r} is incompatible with this filter, which reads "
            f"version {FORMAT_VERSION}; retrain with `denoise-bench train lbf`"
        )
    names = tuple(meta.get("feature_names", ()))
    if names != FEATURE_NAMES:
        extra = sorted(set(names) - set(FEATURE_NAMES))
        missing = sorted(set(FEATURE_NAMES) - set(names))
        raise WeightsError(
            f"{where}: feature list mismatch (file has {len(names)} features, this filter computes "
            f"{len(FEATURE_NAMES)}; unknown {extra}, missing {missing}, or a different order); "
            f"retrain with `denoise-bench train lbf`"
        )
    missing_arrays = [name for name in ARRAYS if name not in stored]
    if missing_arrays:
        raise WeightsError(f"{where}: missing arrays {missing_arrays}")
    for name, shape in SHAPES.items():
        got = stored[name].shape
        if got != shape:
            raise WeightsError(f"{where}: layer {name!r} has shape {got}, expected {shape}")
    arrays = {name: stored[name].astype(np.float32) for name in ARRAYS}
    if arrays_digest(arrays) != meta.get("arrays_sha256"):
        raise WeightsError(f"{where}: checksum mismatch; the weights were altered or corrupted")
    bad = [name for name in ARRAYS if not np.all(np.isfinite(arrays[name]))]
    if bad:
        raise WeightsError(f"{where}: non-finite values in {bad}")
    return LBFWeights(**arrays, meta=meta)
