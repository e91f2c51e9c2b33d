"""The analytic scenes of the ``synthetic`` renderer.

World coordinates are the unit square seen at frame 0; the camera pans by ``pan`` (world units
per frame) along x, and a square object moves by ``object_velocity`` per frame, so motion vectors
and disocclusions are known exactly. Regions: sky (top band, radiance without noise), a back wall,
a checkerboard floor with a hard shadow, and the object. The clean radiance is
``direct + indirect`` with

* ``direct = albedo * sun * max(0, n . l) * lit``  (``lit`` is 0 in the hard shadow),
* ``indirect = albedo * (0.3 + 0.2 Y)``  (smooth ambient).

Each sample multiplies ``direct`` and ``indirect`` by independent unit-mean exponential variates
(shared by the three colour channels, as a path's throughput is), so a pixel mean of ``n``
samples has variance ``(direct^2 + indirect^2) / n`` per channel, exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SKY_TOP = np.array([0.35, 0.55, 1.0], np.float32)
SKY_HORIZON = np.array([0.9, 0.95, 1.0], np.float32)
LIGHT_DIR = np.array([0.5, 0.8, 0.3]) / np.linalg.norm([0.5, 0.8, 0.3])
OBJECT_NORMAL = np.array([0.6, 0.0, 0.8])
SUN = 2.5

SKY, WALL, FLOOR, OBJECT = -1, 0, 1, 2


@dataclass(frozen=True)
class Layout:
    """Parameters of a synthetic scene (``Scene.params``)."""

    pan: float = 0.0
    object_velocity: tuple = (0.0, 0.0)
    object_start: tuple = (0.25, 0.45)
    object_size: float = 0.22
    sky_height: float = 0.15
    horizon: float = 0.6
    checker: int = 8

    @classmethod
    def from_params(cls, params) -> Layout:
        fields = {
            k: (tuple(v) if isinstance(v, list) else v) for k, v in params.items() if k in cls.__dataclass_fields__
        }
        return cls(**fields)

    def camera_offset(self, frame: int) -> float:
        return self.pan * frame

    def object_origin(self, frame: int) -> np.ndarray:
        return np.asarray(self.object_start, float) + frame * np.asarray(self.object_velocity, float)


def world_coordinates(layout: Layout, frame: int, width: int, height: int, jitter=(0.0, 0.0)):
    """World (X, Y) of every pixel centre (plus jitter) in ``frame``; arrays (H, W) float64."""
    x = (np.arange(width) + 0.5 + jitter[0]) / width
    y = (np.arange(height) + 0.5 + jitter[1]) / height
    xx, yy = np.meshgrid(x, y)
    return xx + layout.camera_offset(frame), yy


def classify(layout: Layout, frame: int, xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
    """Region id (SKY, WALL, FLOOR, OBJECT) per pixel."""
    region = np.where(yy < layout.sky_height, SKY, np.where(yy < layout.horizon, WALL, FLOOR))
    ox, oy = layout.object_origin(frame)
    s = layout.object_size
    inside = (xx >= ox) & (xx < ox + s) & (yy >= oy) & (yy < oy + s)
    return np.where(inside, OBJECT, region).astype(np.int32)


def gbuffer(layout: Layout, frame: int, width: int, height: int, jitter=(0.0, 0.0)) -> dict:
    """All G-buffer channels and the clean direct/indirect radiance of ``frame``."""
    xx, yy = world_coordinates(layout, frame, width, height, jitter)
    region = classify(layout, frame, xx, yy)
    h, w = region.shape
    normal = np.zeros((h, w, 3))
    normal[region == WALL] = (0.0, 0.0, 1.0)
    normal[region == FLOOR] = (0.0, 1.0, 0.0)
    normal[region == OBJECT] = OBJECT_NORMAL
    depth = np.full((h, w), np.inf)
    depth[region == WALL] = 6.0
    floor_depth = 2.0 + 4.0 * (1.0 - yy) / max(1.0 - layout.horizon, 1e-6) * 0.4
    depth[region == FLOOR] = floor_depth[region == FLOOR]
    depth[region == OBJECT] = 2.5
    position = np.zeros((h, w, 3))
    hit = region != SKY
    position[..., 0] = np.where(hit, xx * 4.0, 0.0)
    position[..., 1] = np.where(hit, (1.0 - yy) * 3.0, 0.0)
    position[..., 2] = np.where(hit, -np.where(hit, depth, 0.0), 0.0)

    checker = ((np.floor(xx * layout.checker) + np.floor(yy * layout.checker)) % 2).astype(float)
    albedo = np.zeros((h, w, 3))
    albedo[region == WALL] = (0.7, 0.65, 0.55)
    floor_albedo = 0.15 + 0.65 * checker
    albedo[region == FLOOR] = np.stack([floor_albedo] * 3, axis=-1)[region == FLOOR]
    albedo[region == OBJECT] = (0.8, 0.2, 0.15)

    ox, oy = layout.object_origin(frame)
    s = layout.object_size
    in_shadow = (
        (region == FLOOR)
        & (xx >= ox + 0.1)
        & (xx < ox + 0.1 + s)
        & (yy >= layout.horizon)
        & (yy < layout.horizon + 0.2)
    )
    ndotl = np.clip(normal @ LIGHT_DIR, 0.0, None)
    lit = np.where(in_shadow, 0.0, 1.0)
    direct = albedo * (SUN * ndotl * lit)[..., None]
    indirect = albedo * (0.3 + 0.2 * yy)[..., None]
    sky = region == SKY
    t = np.clip(yy / max(layout.sky_height, 1e-6), 0, 1)[..., None]
    sky_color = (1 - t) * SKY_TOP + t * SKY_HORIZON
    return {
        "region": region,
        "xx": xx,
        "yy": yy,
        "normal": normal,
        "depth": depth,
        "position": position,
        "albedo": albedo,
        "direct": direct,
        "indirect": indirect,
        "sky": np.where(sky[..., None], sky_color, 0.0),
        "visibility": np.where(hit, lit * (ndotl > 0), 0.0),
    }


def motion(layout: Layout, frame: int, width: int, height: int, g: dict) -> np.ndarray:
    """Exact motion vectors (H, W, 2) to the previous frame, in pixels."""
    h, w = g["region"].shape
    if frame == 0:
        return np.zeros((h, w, 2), np.float32)
    xx, yy = g["xx"].copy(), g["yy"].copy()
    obj = g["region"] == OBJECT
    delta = layout.object_origin(frame - 1) - layout.object_origin(frame)
    xx[obj] += delta[0]
    yy[obj] += delta[1]
    prev_u = xx - layout.camera_offset(frame - 1)
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    mx = prev_u * width - 0.5 - jj
    my = yy * height - 0.5 - ii
    return np.stack([mx, my], axis=-1).astype(np.float32)
