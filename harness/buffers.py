"""Frames and their named channels.

A :class:`Frame` is one frame of renderer output handed to a filter: named NumPy arrays that
all share the image size H x W, plus :class:`FrameMeta`. Conventions:

* pixel (row ``i``, column ``j``) has its centre at image coordinates ``(x, y) = (j, i)``;
  ``x`` grows to the right, ``y`` downwards;
* ``motion[i, j] = (dx, dy)``: the surface seen at pixel (i, j) was at image coordinates
  ``(j + dx, i + dy)`` in the previous frame;
* ``depth`` is the positive view-space z (distance along the camera's viewing axis), ``inf``
  for background; background pixels have ``object_id == -1`` and zero normal, position and
  albedo.

The converged reference is never part of a frame.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: channel name -> (components, dtype, meaning)
CHANNELS: Mapping[str, tuple[int, type, str]] = {
    "color": (3, np.float32, "noisy linear HDR radiance, mean of the pixel's samples"),
    "direct": (3, np.float32, "colour from directly lit paths (direct + indirect = color)"),
    "indirect": (3, np.float32, "colour from paths with two or more bounces"),
    "albedo": (3, np.float32, "first-hit surface albedo (textured)"),
    "emission": (3, np.float32, "radiance emitted by the first-hit surface (part of color)"),
    "normal": (3, np.float32, "first-hit world-space shading normal, unit length"),
    "depth": (1, np.float32, "first-hit view-space depth; inf for background"),
    "position": (3, np.float32, "first-hit world position"),
    "object_id": (1, np.int32, "mesh/object id, -1 for background"),
    "motion": (2, np.float32, "offset in pixels to this surface point in the previous frame"),
    "variance": (3, np.float32, "per-pixel variance of the sample mean"),
    "spp": (1, np.int32, "samples taken per pixel"),
    "visibility": (1, np.float32, "fraction of first-hit shadow rays that reached a light"),
}

#: the key of a frame's metadata in :meth:`Frame.to_arrays`
META_KEY = "__meta__"


class ChannelError(ValueError):
    """A channel has the wrong name, shape or dtype, or holds non-finite values."""


class NonFiniteError(ChannelError):
    """A channel holds NaN or Inf where finite values are required."""


def expected_shape(name: str, height: int, width: int) -> tuple[int, ...]:
    """Shape of channel ``name`` for an image of ``height`` x ``width`` pixels."""
    comps = CHANNELS[name][0]
    return (height, width) if comps == 1 else (height, width, comps)


def check_channel(name: str, array: Any, height: int, width: int, *, owner: str = "frame") -> None:
    """Validate one channel; raise :class:`ChannelError` naming owner, channel, expected, actual."""
    if name not in CHANNELS:
        raise ChannelError(f"{owner}: unknown channel {name!r}; known channels are {sorted(CHANNELS)}")
    if not isinstance(array, np.ndarray):
        raise ChannelError(f"{owner}: channel {name!r} must be a numpy array, got {type(array).__name__}")
    want_shape = expected_shape(name, height, width)
    want_dtype = np.dtype(CHANNELS[name][1])
    if array.shape != want_shape or array.dtype != want_dtype:
        raise ChannelError(
            f"{owner}: channel {name!r} expected shape {want_shape} dtype {want_dtype}, "
            f"got shape {array.shape} dtype {array.dtype}"
        )


@dataclass(frozen=True)
class FrameMeta:
    """Metadata of a frame.

    Attributes
    ----------
    index : int
        Frame index within the sequence.
    scene : str
        Scene name.
    seed : int
        Seed of the noise of this frame.
    view_proj, prev_view_proj : ndarray (4, 4) or None
        World-to-clip matrices of this and the previous frame.
    jitter : (float, float)
        Sub-pixel offset of the projection, in pixels.
    camera_cut : bool
        True when history must not be used (first frame, cut).
    extra : mapping
        Renderer-specific values (e.g. ``max_depth`` of the scene).
    """

    index: int = 0
    scene: str = ""
    seed: int = 0
    view_proj: np.ndarray | None = None
    prev_view_proj: np.ndarray | None = None
    jitter: tuple = (0.0, 0.0)
    camera_cut: bool = False
    extra: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict:
        """The metadata as JSON-able data (matrices as nested lists); see :meth:`from_dict`."""
        def matrix(value):
            return None if value is None else np.asarray(value, np.float64).tolist()

        return {
            "index": int(self.index),
            "scene": self.scene,
            "seed": int(self.seed),
            "view_proj": matrix(self.view_proj),
            "prev_view_proj": matrix(self.prev_view_proj),
            "jitter": [float(v) for v in self.jitter],
            "camera_cut": bool(self.camera_cut),
            "extra": dict(self.extra),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> FrameMeta:
        """Metadata from :meth:`to_dict`'s output (missing fields take their defaults)."""
        def matrix(value):
            return None if value is None else np.asarray(value, np.float64)

        return cls(
            index=int(data.get("index", 0)),
            scene=str(data.get("scene", "")),
            seed=int(data.get("seed", 0)),
            view_proj=matrix(data.get("view_proj")),
            prev_view_proj=matrix(data.get("prev_view_proj")),
            jitter=tuple(float(v) for v in data.get("jitter", (0.0, 0.0))),
            camera_cut=bool(data.get("camera_cut", False)),
            extra=dict(data.get("extra", {})),
        )


class Frame:
    """Named, validated channels of one frame.

    Parameters
    ----------
    channels : mapping of str to ndarray
        Must contain ``color``; every array is validated against :data:`CHANNELS`.
    meta : FrameMeta, optional
    owner : str
        Named in validation errors (the plugin that produced the frame).

    Notes
    -----
    Arrays are made read-only so that a filter cannot modify its input in place.
    """

    __slots__ = ("_channels", "meta", "height", "width")

    def __init__(self, channels: Mapping[str, np.ndarray], meta: FrameMeta | None = None, *, owner: str = "frame"):
        if "color" not in channels:
            raise ChannelError(f"{owner}: a frame needs a 'color' channel; got {sorted(channels)}")
        color = channels["color"]
        if not isinstance(color, np.ndarray) or color.ndim != 3:
            shape = getattr(color, "shape", None)
            raise ChannelError(f"{owner}: channel 'color' expected shape (H, W, 3) float32, got shape {shape}")
        height, width = color.shape[:2]
        if height < 1 or width < 1:
            raise ChannelError(f"{owner}: channel 'color' must have at least 1x1 pixels, got {color.shape}")
        stored = {}
        for name, array in channels.items():
            check_channel(name, array, height, width, owner=owner)
            if array.flags.writeable:
                array = array.copy()
                array.flags.writeable = False
            stored[name] = array
        self._channels = stored
        self.meta = meta or FrameMeta()
        self.height = height
        self.width = width

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self._channels[name]
        except KeyError:
            raise KeyError(
                f"frame of scene {self.meta.scene!r} has no channel {name!r}; it has {sorted(self._channels)}"
            ) from None

    def __contains__(self, name: object) -> bool:
        return name in self._channels

    def get(self, name: str, default=None):
        """Channel ``name`` or ``default``."""
        return self._channels.get(name, default)

    @property
    def channels(self) -> frozenset[str]:
        """Names of the channels present."""
        return frozenset(self._channels)

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width)."""
        return (self.height, self.width)

    def arrays(self) -> dict[str, np.ndarray]:
        """A new dict of the (read-only) arrays."""
        return dict(self._channels)

    def subset(self, names) -> Frame:
        """A frame with only ``names`` (plus ``color``); missing names raise ``KeyError``."""
        keep = set(names) | {"color"}
        return Frame({n: self[n] for n in sorted(keep)}, self.meta)

    def replace(self, meta: FrameMeta | None = None, **arrays: np.ndarray) -> Frame:
        """A frame with some channels (or the metadata) replaced."""
        merged = dict(self._channels)
        merged.update(arrays)
        return Frame(merged, meta or self.meta)

    def with_meta(self, **changes) -> Frame:
        """A frame with some metadata fields changed."""
        return Frame(self._channels, dataclasses.replace(self.meta, **changes))

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The channels plus the metadata (JSON bytes under ``__meta__``), for ``np.savez``.

        :meth:`from_arrays` restores the frame bit for bit.
        """
        arrays = dict(self._channels)
        arrays[META_KEY] = np.frombuffer(json.dumps(self.meta.to_dict()).encode(), np.uint8)
        return arrays

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], *, owner: str = "frame") -> Frame:
        """The frame stored by :meth:`to_arrays` (validated like any frame)."""
        arrays = dict(arrays)
        raw = arrays.pop(META_KEY, None)
        meta = FrameMeta.from_dict(json.loads(bytes(np.asarray(raw, np.uint8)).decode())) if raw is not None else None
        return cls(arrays, meta, owner=owner)

    def __repr__(self) -> str:
        return f"Frame({self.height}x{self.width}, channels={sorted(self._channels)}, index={self.meta.index})"


def check_filter_output(out: Any, frame: Frame, *, owner: str) -> np.ndarray:
    """Validate a filter's output against its input frame.

    Raises :class:`ChannelError` for a non-array, wrong shape or dtype, and
    :class:`NonFiniteError` for NaN/Inf values.
    """
    want = (frame.height, frame.width, 3)
    if not isinstance(out, np.ndarray):
        raise ChannelError(f"{owner}: output expected ndarray of shape {want} float32, got {type(out).__name__}")
    if out.shape != want or out.dtype != np.float32:
        raise ChannelError(
            f"{owner}: output expected shape {want} dtype float32, got shape {out.shape} dtype {out.dtype}"
        )
    bad = int(np.count_nonzero(~np.isfinite(out)))
    if bad:
        raise NonFiniteError(f"{owner}: output holds {bad} non-finite values")
    return out
