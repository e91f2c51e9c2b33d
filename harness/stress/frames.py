"""Frames of the stress battery: a plausible two-surface scene, flat frames, and edits of them.

Every builder returns a :class:`harness.Frame` holding exactly the channels asked for (plus
``color``), so a filter sees what it declared. The scene is two surfaces split at the middle
column (different normal, albedo, depth and object id) under a vertical light gradient:
``color = albedo * gradient``, times exponential noise of mean one where ``noise`` is true.
"""

from __future__ import annotations

import numpy as np

from harness.buffers import Frame, FrameMeta

#: fraction of direct light in the colour of a frame that has ``direct``/``indirect``
DIRECT_SHARE = np.float32(0.6)
#: RGB of the flat frames
FLAT_RGB = np.array([0.25, 0.5, 0.75], np.float32)


def scene_frame(height: int, width: int, channels, *, seed: int = 0, index: int = 0, noise: bool = True,
                camera_cut: bool | None = None) -> Frame:
    """The two-surface scene at ``height`` x ``width`` with ``channels``.

    Parameters
    ----------
    height, width : int
    channels : iterable of str
        Channels to include (``color`` is always there).
    seed : int
        Seed of the noise.
    index : int
        Frame index (``camera_cut`` defaults to ``index == 0``).
    noise : bool
        Multiply the clean colour by exponential noise of mean one (a 1-spp look).
    camera_cut : bool, optional
    """
    shape = (height, width)
    jj, ii = np.meshgrid(np.arange(width), np.arange(height))
    right = jj >= width // 2
    albedo = np.where(right[..., None], np.float32(0.3), np.float32(0.7)) * np.ones(3, np.float32)
    gradient = (0.5 + 0.5 * ii / max(height - 1, 1))[..., None]
    clean = albedo * gradient
    if noise:
        clean = clean * np.random.default_rng(seed).exponential(1.0, size=(*shape, 1))
    normal = np.zeros((*shape, 3), np.float32)
    normal[...] = (0.0, 0.0, 1.0)
    normal[right] = (0.6, 0.0, 0.8)
    depth = np.where(right, 3.0, 2.0).astype(np.float32)
    guides = {
        "albedo": albedo.astype(np.float32),
        "normal": normal,
        "depth": depth,
        "position": np.stack([jj * 0.01, ii * 0.01, -depth], axis=-1).astype(np.float32),
        "object_id": right.astype(np.int32),
        "variance": np.full((*shape, 3), 0.05 if noise else 0.0, np.float32),
    }
    cut = index == 0 if camera_cut is None else camera_cut
    return _frame(clean.astype(np.float32), guides, channels, FrameMeta(index=index, scene="stress", seed=seed,
                                                                        camera_cut=cut))


def flat_frame(height: int, width: int, channels, *, level=FLAT_RGB, index: int = 0,
               camera_cut: bool | None = None) -> Frame:
    """A flat frame: constant colour ``level`` (scalar or RGB) over one constant surface."""
    shape = (height, width)
    color = np.broadcast_to(np.asarray(level, np.float32), (*shape, 3)).astype(np.float32)
    guides = {
        "albedo": np.full((*shape, 3), 0.5, np.float32),
        "normal": np.broadcast_to(np.float32([0.0, 0.0, 1.0]), (*shape, 3)).copy(),
        "depth": np.full(shape, 2.0, np.float32),
        "position": np.broadcast_to(np.float32([0.1, 0.2, -2.0]), (*shape, 3)).copy(),
        "object_id": np.zeros(shape, np.int32),
        "variance": np.zeros((*shape, 3), np.float32),
    }
    cut = index == 0 if camera_cut is None else camera_cut
    return _frame(color, guides, channels, FrameMeta(index=index, scene="stress-flat", camera_cut=cut))


def _frame(color: np.ndarray, guides: dict, channels, meta: FrameMeta) -> Frame:
    shape = color.shape[:2]
    arrays = {
        **guides,
        "emission": np.zeros((*shape, 3), np.float32),
        "motion": np.zeros((*shape, 2), np.float32),
        "spp": np.ones(shape, np.int32),
        "visibility": np.ones(shape, np.float32),
    }
    arrays.update(split_radiance(color))
    names = set(channels) | {"color"}
    return Frame({n: arrays[n] for n in names}, meta)


def split_radiance(color: np.ndarray) -> dict:
    """``color`` and its ``direct``/``indirect`` split (``DIRECT_SHARE`` of it direct)."""
    color = np.asarray(color, np.float32)
    direct = (color * DIRECT_SHARE).astype(np.float32)
    with np.errstate(invalid="ignore", over="ignore"):
        indirect = (color - direct).astype(np.float32)
    return {"color": color, "direct": direct, "indirect": indirect}


def with_color(frame: Frame, color: np.ndarray) -> Frame:
    """``frame`` with new colour; ``direct``/``indirect`` follow it where the frame has them.

    A check that perturbs the colour must perturb every radiance channel a filter reads: a
    filter that filters ``direct`` and ``indirect`` (SVGF) never looks at ``color``.
    """
    parts = split_radiance(color)
    return frame.replace(**{n: a for n, a in parts.items() if n == "color" or n in frame})


def with_background(frame: Frame, mask: np.ndarray) -> Frame:
    """``frame`` with the pixels of ``mask`` made background (the conventions of :mod:`harness.buffers`)."""
    values = {"normal": 0.0, "position": 0.0, "albedo": 0.0, "depth": np.inf, "object_id": -1, "motion": 0.0}
    changed = {}
    for name, value in values.items():
        if name in frame:
            array = np.array(frame[name], copy=True)
            array[mask] = value
            changed[name] = array
    return frame.replace(**changed)


def set_pixels(frame: Frame, name: str, mask: np.ndarray, value) -> Frame:
    """``frame`` with channel ``name`` set to ``value`` (every component) on the pixels of ``mask``.

    Setting ``color`` keeps ``direct``/``indirect`` consistent (:func:`with_color`).
    """
    array = np.array(frame[name], copy=True)
    array[mask] = value
    return with_color(frame, array) if name == "color" else frame.replace(**{name: array})


def scattered(height: int, width: int, fraction: float = 0.05, seed: int = 7) -> np.ndarray:
    """A boolean mask of about ``fraction`` of the pixels (at least one), spread over the image."""
    rng = np.random.default_rng(seed)
    count = max(1, int(round(fraction * height * width)))
    mask = np.zeros(height * width, bool)
    mask[rng.choice(height * width, size=count, replace=False)] = True
    return mask.reshape(height, width)
