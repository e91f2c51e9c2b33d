"""Camera paths of Mitsuba scenes: the generated default path, the bounds check, rays against the triangles.

**Scene bounds.** The axis-aligned box of the scene's triangles and of the file's own camera
position (a camera placed outside the geometry, looking at it, is inside its scene). A path
whose eye leaves the box on any frame is refused (:func:`check_inside`).

**The default path** (:func:`default_path`), for a scene without camera keys: from the file's
camera, a dolly along the view direction (or away from it, whichever has more room) and a pan
about the camera's up axis, both at constant speed, so that every frame moves and any first
``N`` frames of the path move at the same rate. Its size is measured with rays cast from the
camera against the scene's triangles:

- the dolly covers at most :data:`DOLLY_FRACTION` of the distance to the closest surface within
  :data:`CONE` degrees of its direction (so the camera stays in front of the geometry nearest to
  it and never passes through a surface), at most :data:`DOLLY_MAX` of the scene's bounding-box
  diagonal, and stays in the scene's bounds; it goes forward unless backward allows more than
  twice the distance;
- the pan turns :data:`PAN` degrees in all, towards the side where the last frame's view has the
  farther surfaces (median distance of a grid of rays through that view).
"""

from __future__ import annotations

import numpy as np

from .animation import AnimationError

#: total pan of the default path, degrees
PAN = 12.0
#: the dolly covers at most this fraction of the free distance ahead of it
DOLLY_FRACTION = 0.3
#: and at most this fraction of the scene's bounding-box diagonal
DOLLY_MAX = 0.05
#: half-angle of the cone of rays that measures the free distance, degrees
CONE = 25.0
#: rays per batch of the triangle tests (each batch holds a few (rays x triangles) float64 arrays)
BATCH = 16


def scene_bounds(vertices: np.ndarray, eye) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) corners of the box of the triangles ``vertices`` (T, 3, 3) and the point ``eye``."""
    points = np.concatenate([np.asarray(vertices, np.float64).reshape(-1, 3), np.asarray(eye, np.float64)[None]])
    return points.min(axis=0), points.max(axis=0)


def check_inside(positions: np.ndarray, low: np.ndarray, high: np.ndarray, where: str) -> None:
    """Raise :class:`AnimationError` (one line) at the first frame whose eye lies outside the box."""
    margin = 1e-6 * (1.0 + float(np.linalg.norm(high - low)))
    outside = ((positions < low - margin) | (positions > high + margin)).any(axis=1)
    if outside.any():
        t = int(np.argmax(outside))
        raise AnimationError(
            f"{where}: the camera path leaves the scene bounds at frame {t}: eye {_fmt(positions[t])} is outside "
            f"the box {_fmt(low)} to {_fmt(high)} of the geometry and the file's camera")


class RaysFrom:
    """Closest-hit distances of rays from one origin against a triangle soup (numpy, no BVH).

    The Moeller-Trumbore test rearranged so that everything depending only on the origin and the
    triangles is computed once and each batch of rays is three matrix products.

    Parameters
    ----------
    origin : (3,)
    vertices : ndarray (T, 3, 3)
    """

    def __init__(self, origin, vertices: np.ndarray):
        v = np.asarray(vertices, np.float64).reshape(-1, 3, 3)
        e1, e2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
        tvec = np.asarray(origin, np.float64) - v[:, 0]
        self.normal = np.cross(e1, e2)  # det = -d . normal
        self.a = np.cross(e2, tvec)  # u det = d . a
        self.q = np.cross(tvec, e1)  # v det = d . q
        self.tq = np.einsum("ij,ij->i", e2, self.q)  # t det = e2 . q
        scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
        self.tiny = 1e-12 * np.maximum(scale, 1e-300)

    def closest(self, directions: np.ndarray) -> np.ndarray:
        """Distance to the closest triangle along each unit direction (R, 3); inf where none is hit."""
        d = np.atleast_2d(np.asarray(directions, np.float64))
        out = np.full(len(d), np.inf)
        if len(self.tq) == 0:
            return out
        for start in range(0, len(d), BATCH):
            part = d[start:start + BATCH]
            det = -(part @ self.normal.T)
            ok = np.abs(det) > self.tiny
            inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
            u = (part @ self.a.T) * inv
            v = (part @ self.q.T) * inv
            t = self.tq * inv
            hit = ok & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > 1e-9)
            out[start:start + BATCH] = np.where(hit, t, np.inf).min(axis=1)
        return out


def cone(axis: np.ndarray, half_angle: float, rings: int = 2, per_ring: int = 8) -> np.ndarray:
    """Unit directions: ``axis`` and ``rings`` rings of ``per_ring`` directions up to ``half_angle`` degrees."""
    axis = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b1 = np.cross(axis, helper)
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(axis, b1)
    out = [axis]
    for r in range(1, rings + 1):
        theta = np.radians(half_angle) * r / rings
        for k in range(per_ring):
            phi = 2.0 * np.pi * (k + 0.5 * (r % 2)) / per_ring
            out.append(np.cos(theta) * axis + np.sin(theta) * (np.cos(phi) * b1 + np.sin(phi) * b2))
    return np.array(out)


def view_grid(forward, right, up, tan_half: float, aspect: float, nx: int = 5, ny: int = 3) -> np.ndarray:
    """Unit directions through an ``nx`` x ``ny`` grid of a pinhole view (corners included)."""
    xs = np.linspace(-1.0, 1.0, nx) * tan_half * aspect
    ys = np.linspace(-1.0, 1.0, ny) * tan_half
    d = np.array([forward + x * right + y * up for y in ys for x in xs])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def default_path(vertices: np.ndarray, camera, frames: int, aspect: float) -> dict:
    """The generated path of ``frames`` frames from ``camera``'s first frame (see the module docstring).

    Returns
    -------
    dict
        ``positions``, ``targets`` (F, 3), and ``dolly`` (distance, scene units), ``direction``
        (``"forward"`` or ``"backward"``), ``pan`` (signed degrees about the up axis, positive to
        the left) for the record.
    """
    eye = np.asarray(camera.eye(0), np.float64)
    right, up, forward = camera.basis(0)
    low, high = scene_bounds(vertices, eye)
    diagonal = float(np.linalg.norm(high - low))
    rays = RaysFrom(eye, vertices)
    allowed = {}
    for direction, label in ((forward, "forward"), (-forward, "backward")):
        room = float(rays.closest(cone(direction, CONE)).min())
        allowed[label] = max(min(DOLLY_FRACTION * room, DOLLY_MAX * diagonal,
                                 0.9 * _inside_distance(eye, direction, low, high)), 0.0)
    label = "forward" if allowed["forward"] >= 0.5 * allowed["backward"] else "backward"
    direction, dolly = (forward if label == "forward" else -forward), allowed[label]
    last_eye = eye + direction * dolly
    distance = float(np.linalg.norm(np.asarray(camera.targets[0]) - eye)) or 1.0
    tan_half = float(np.tan(np.radians(camera.fov_at(0)) / 2.0))
    pan, far = PAN, -1.0
    end_rays = RaysFrom(last_eye, vertices)
    for sign in (1.0, -1.0):
        f = _turn(forward, up, sign * PAN)
        r = np.cross(f, up)
        r /= np.linalg.norm(r)
        hits = end_rays.closest(view_grid(f, r, np.cross(r, f), tan_half, aspect))
        typical = float(np.median(np.minimum(hits, 1e30)))
        if typical > far:
            pan, far = sign * PAN, typical
    s = np.linspace(0.0, 1.0, frames) if frames > 1 else np.zeros(1)
    positions = eye + s[:, None] * dolly * direction
    targets = np.array([p + _turn(forward, up, pan * k) * distance for p, k in zip(positions, s)])
    return {"positions": positions, "targets": targets, "dolly": float(dolly), "direction": label,
            "pan": float(pan if frames > 1 else 0.0)}


def crossings(positions: np.ndarray, vertices: np.ndarray) -> list[int]:
    """Frames ``t`` whose move from frame ``t - 1`` passes through a triangle."""
    out = []
    for t in range(1, len(positions)):
        step = positions[t] - positions[t - 1]
        length = float(np.linalg.norm(step))
        if length == 0.0:
            continue
        if RaysFrom(positions[t - 1], vertices).closest(step / length)[0] <= length:
            out.append(t)
    return out


def _turn(vector: np.ndarray, axis: np.ndarray, degrees: float) -> np.ndarray:
    """``vector`` rotated about the unit ``axis`` (Rodrigues)."""
    a = np.radians(degrees)
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    v = np.asarray(vector, np.float64)
    return v * np.cos(a) + np.cross(k, v) * np.sin(a) + k * np.dot(k, v) * (1.0 - np.cos(a))


def _inside_distance(point: np.ndarray, direction: np.ndarray, low: np.ndarray, high: np.ndarray) -> float:
    """How far ``point`` can move along ``direction`` before leaving the box (0 when it is on its face)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_high = np.where(direction > 0, (high - point) / direction, np.inf)
        t_low = np.where(direction < 0, (low - point) / direction, np.inf)
    return float(max(min(t_high.min(), t_low.min()), 0.0))


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


__all__ = ["CONE", "DOLLY_FRACTION", "DOLLY_MAX", "PAN", "RaysFrom", "check_inside", "crossings", "default_path",
           "scene_bounds"]
