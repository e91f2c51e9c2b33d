"""Small procedural frames for conformance checks (no renderer plugin needed)."""

from __future__ import annotations

import numpy as np

from harness.buffers import CHANNELS, Frame, FrameMeta


def make_frame(
    height: int = 16,
    width: int = 12,
    channels=None,
    *,
    seed: int = 0,
    index: int = 0,
    color: np.ndarray | float | None = None,
    constant_features: bool = False,
) -> Frame:
    """A plausible frame with every channel in ``channels`` (default: all of :data:`CHANNELS`).

    Parameters
    ----------
    height, width : int
    channels : iterable of str, optional
    seed : int
        Seed of the random content.
    index : int
        Frame index; ``camera_cut`` is set for index 0.
    color : ndarray or float, optional
        Overrides the colour (a float gives a constant image).
    constant_features : bool
        Make every feature channel constant over the image (for the constant-image check).
    """
    rng = np.random.default_rng(seed)
    names = set(CHANNELS if channels is None else channels) | {"color"}
    shape = (height, width)
    jj, ii = np.meshgrid(np.arange(width), np.arange(height))
    split = jj >= width // 2 if not constant_features else np.zeros(shape, bool)
    normal = np.zeros((*shape, 3), np.float32)
    normal[...] = (0.0, 0.0, 1.0)
    normal[split] = (0.6, 0.0, 0.8)
    albedo = np.where(split[..., None], np.float32(0.3), np.float32(0.7)) * np.ones(3, np.float32)
    depth = np.where(split, 3.0, 2.0).astype(np.float32) if not constant_features else np.full(shape, 2.0, np.float32)
    position = np.stack([jj * 0.01, ii * 0.01, -depth], axis=-1).astype(np.float32)
    if constant_features:
        position[...] = (0.1, 0.2, -2.0)
    if color is None:
        clean = albedo * (0.5 + 0.5 * (ii / max(height - 1, 1)))[..., None]
        rgb = (clean * rng.exponential(1.0, size=(*shape, 1))).astype(np.float32)
    else:
        rgb = np.broadcast_to(np.asarray(color, np.float32), (*shape, 3)).astype(np.float32).copy()
    arrays = {
        "color": rgb,
        "direct": (rgb * 0.6).astype(np.float32),
        "indirect": (rgb - rgb * 0.6).astype(np.float32),
        "albedo": albedo.astype(np.float32),
        "emission": np.zeros((*shape, 3), np.float32),
        "normal": normal,
        "depth": depth,
        "position": position,
        "object_id": split.astype(np.int32),
        "motion": np.zeros((*shape, 2), np.float32),
        "variance": np.full((*shape, 3), 0.05, np.float32) if color is None else np.zeros((*shape, 3), np.float32),
        "spp": np.ones(shape, np.int32),
        "visibility": np.ones(shape, np.float32),
    }
    return Frame(
        {n: arrays[n] for n in names}, FrameMeta(index=index, scene="conformance", seed=seed, camera_cut=index == 0)
    )
