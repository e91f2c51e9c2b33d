"""Procedural mesh primitives for the built-in scenes.

Every builder returns a :class:`Part`: plain triangle arrays (points, faces, per-point ``uv`` and
``normal``, per-face material index) that are cheap to transform and concatenate; :func:`to_polydata`
turns a list of parts into one ``pyvista.PolyData`` in the layout :class:`harness.SceneObject`
expects (point data ``uv``/``normal``, cell data ``material``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyvista as pv

from harness import rotation, translation


@dataclass
class Part:
    """Triangles with per-point uv and normal, and a material index per face.

    Attributes
    ----------
    points : ndarray (n, 3) float64
    faces : ndarray (t, 3) int64
    uv : ndarray (n, 2) float64
    normals : ndarray (n, 3) float64
    material : ndarray (t,) int32
    """

    points: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    normals: np.ndarray
    material: np.ndarray

    def transformed(self, matrix: np.ndarray) -> Part:
        """The part moved by the 4x4 affine ``matrix`` (normals by its inverse transpose)."""
        m = np.asarray(matrix, float)
        pts = self.points @ m[:3, :3].T + m[:3, 3]
        nrm = self.normals @ np.linalg.inv(m[:3, :3])
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
        faces = self.faces if np.linalg.det(m[:3, :3]) > 0 else self.faces[:, ::-1]
        return Part(pts, faces.copy(), self.uv.copy(), nrm, self.material.copy())

    def flipped(self) -> Part:
        """The part with reversed winding and normals (for inward-facing shells)."""
        return Part(self.points.copy(), self.faces[:, ::-1].copy(), self.uv.copy(), -self.normals, self.material.copy())


def merge(parts: list[Part]) -> Part:
    """Concatenate parts into one."""
    offsets = np.cumsum([0] + [len(p.points) for p in parts[:-1]])
    return Part(
        np.concatenate([p.points for p in parts]),
        np.concatenate([p.faces + o for p, o in zip(parts, offsets)]),
        np.concatenate([p.uv for p in parts]),
        np.concatenate([p.normals for p in parts]),
        np.concatenate([p.material for p in parts]),
    )


def to_polydata(parts: Part | list[Part]) -> pv.PolyData:
    """One triangle ``PolyData`` with point data ``uv``/``normal`` and cell data ``material``."""
    part = merge(parts) if isinstance(parts, list) else parts
    a, b, c = (part.points[part.faces[:, k]] for k in range(3))
    keep = np.linalg.norm(np.cross(b - a, c - a), axis=1) > 1e-12
    part = Part(part.points, part.faces[keep], part.uv, part.normals, part.material[keep])
    faces = np.hstack([np.full((len(part.faces), 1), 3), part.faces]).astype(np.int64).ravel()
    mesh = pv.PolyData(part.points.astype(np.float32), faces=faces)
    mesh.point_data["uv"] = part.uv.astype(np.float32)
    mesh.point_data["normal"] = part.normals.astype(np.float32)
    mesh.cell_data["material"] = part.material.astype(np.int32)
    return mesh


# --------------------------------------------------------------------------- builders


def grid(corner, edge_u, edge_v, material: int, nu: int = 1, nv: int = 1, uv_scale=(1.0, 1.0)) -> Part:
    """A flat parallelogram ``corner + s*edge_u + t*edge_v`` split into ``nu x nv`` quads.

    The normal is ``edge_u x edge_v``; ``uv`` runs from 0 to ``uv_scale``.
    """
    corner, eu, ev = (np.asarray(v, float) for v in (corner, edge_u, edge_v))
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    pts = corner + s.reshape(-1, 1) * eu + t.reshape(-1, 1) * ev
    uv = np.stack([s.ravel() * uv_scale[0], t.ravel() * uv_scale[1]], axis=1)
    n = np.cross(eu, ev)
    n = n / np.linalg.norm(n)
    faces = _grid_faces(nu, nv)
    return Part(pts, faces, uv, np.tile(n, (len(pts), 1)), np.full(len(faces), material, np.int32))


def _grid_faces(nu: int, nv: int) -> np.ndarray:
    """Two counter-clockwise triangles per cell of an (nu+1) x (nv+1) point grid (row-major in u)."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * (nv + 1) + j).ravel()
    b = a + (nv + 1)
    return np.concatenate([np.stack([a, b, b + 1], 1), np.stack([a, b + 1, a + 1], 1)])


def box(lo, hi, material: int, uv_density: float = 1.0) -> Part:
    """An axis-aligned box from ``lo`` to ``hi`` with flat outward faces; uv in world units x density."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    size = hi - lo
    sx, sy, sz = size
    x, y, z = np.eye(3)
    faces = [
        (lo, z * sz, y * sy, (sz, sy)),  # -x
        (lo + x * sx, y * sy, z * sz, (sy, sz)),  # +x
        (lo, x * sx, z * sz, (sx, sz)),  # -y
        (lo + y * sy, z * sz, x * sx, (sz, sx)),  # +y
        (lo, y * sy, x * sx, (sy, sx)),  # -z
        (lo + z * sz, x * sx, y * sy, (sx, sy)),  # +z
    ]
    return merge([grid(c, u, v, material, uv_scale=(a * uv_density, b * uv_density)) for c, u, v, (a, b) in faces])


def cylinder(radius: float, height: float, material: int, segments: int = 16, caps: bool = True,
             radius_top: float | None = None) -> Part:
    """A (possibly tapered) cylinder on the y axis from y=0 to ``height``, smooth sides."""
    rt = radius if radius_top is None else radius_top
    ang = np.linspace(0.0, 2 * np.pi, segments + 1)
    c, s = np.cos(ang), np.sin(ang)
    bottom = np.stack([radius * c, np.zeros_like(c), radius * s], 1)
    top = np.stack([rt * c, np.full_like(c, height), rt * s], 1)
    slope = (radius - rt) / height
    n = np.stack([c, np.full_like(c, slope), s], 1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    pts = np.concatenate([bottom, top])
    nrm = np.concatenate([n, n])
    uv = np.concatenate([np.stack([ang / (2 * np.pi), np.zeros_like(ang)], 1),
                         np.stack([ang / (2 * np.pi), np.ones_like(ang)], 1)])
    k = np.arange(segments)
    m = segments + 1
    faces = np.concatenate([np.stack([k, k + m, k + m + 1], 1), np.stack([k, k + m + 1, k + 1], 1)])
    side = Part(pts, faces, uv, nrm, np.full(len(faces), material, np.int32))
    if not caps:
        return side
    return merge([side, disk(rt, material, segments).transformed(translation((0, height, 0))),
                  disk(radius, material, segments).transformed(rotation((1, 0, 0), 180))])


def disk(radius: float, material: int, segments: int = 16) -> Part:
    """A disk of ``radius`` in the y=0 plane facing +y."""
    ang = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    rim = np.stack([radius * np.cos(ang), np.zeros_like(ang), radius * np.sin(ang)], 1)
    pts = np.concatenate([[[0.0, 0.0, 0.0]], rim])
    k = np.arange(segments)
    faces = np.stack([np.zeros(segments, int), (k + 1) % segments + 1, k + 1], 1)
    uv = pts[:, [0, 2]] / (2 * radius) + 0.5
    nrm = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    return Part(pts, faces, uv, nrm, np.full(segments, material, np.int32))


def sphere(radius: float, material: int, rings: int = 12, segments: int = 24) -> Part:
    """A UV sphere centred at the origin with outward smooth normals."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    n = np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    uv = np.stack([p.ravel() / (2 * np.pi), 1.0 - t.ravel() / np.pi], 1)
    faces = _grid_faces(rings, segments)
    # drop the degenerate triangles at the poles
    a, b, c = (n[faces[:, k]] for k in range(3))
    area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    faces = faces[area > 1e-12]
    return Part(n * radius, faces, uv, n.copy(), np.full(len(faces), material, np.int32))


def arch_panel(width: float, spring: float, top: float, depth: float, material: int, segments: int = 12) -> Part:
    """A wall panel with a semicircular arch opening, in the x-y plane, extruded along z.

    The panel spans x in [-width/2, width/2], y in [0, top], z in [0, depth]; the opening is a
    rectangle up to ``spring`` closed by a half circle of radius width/2 (``top`` must be above
    ``spring + width/2``). Returns the two faces and the curved intrados (the opening's sides
    below ``spring`` are left open: columns stand there).
    """
    r = width / 2.0
    corner = np.arctan2(top - spring, r)
    ang = np.unique(np.concatenate([np.linspace(0, np.pi, segments + 1), [corner, np.pi - corner]]))
    inner = np.stack([r * np.cos(ang), spring + r * np.sin(ang)], 1)
    c, s = np.cos(ang), np.sin(ang)
    with np.errstate(divide="ignore"):
        t_side = np.where(np.abs(c) > 1e-12, r / np.abs(c), np.inf)
        t_top = np.where(s > 1e-12, (top - spring) / s, np.inf)
    t = np.minimum(t_side, t_top)
    outer = np.stack([t * c, spring + t * s], 1)
    parts = []
    for z, sign in ((0.0, -1.0), (depth, 1.0)):
        pts2 = np.concatenate([inner, outer])
        pts = np.column_stack([pts2, np.full(len(pts2), z)])
        k = np.arange(len(ang) - 1)
        m = len(ang)
        faces = np.concatenate([np.stack([k, k + m, k + m + 1], 1), np.stack([k, k + m + 1, k + 1], 1)])
        if sign < 0:
            faces = faces[:, ::-1]
        nrm = np.tile([0.0, 0.0, sign], (len(pts), 1))
        uv = pts2 / max(width, 1e-9)
        parts.append(Part(pts, faces, uv, nrm, np.full(len(faces), material, np.int32)))
    # intrados: the curved underside, normals pointing to the arch centre
    n = len(ang)
    pts = np.concatenate([np.column_stack([inner, np.zeros(n)]), np.column_stack([inner, np.full(n, depth)])])
    nrm2 = -np.stack([c, s], 1)
    nrm = np.column_stack([np.concatenate([nrm2, nrm2]), np.zeros(2 * n)])
    k = np.arange(n - 1)
    faces = np.concatenate([np.stack([k, k + n, k + n + 1], 1), np.stack([k, k + n + 1, k + 1], 1)])
    uv = np.column_stack([np.concatenate([ang, ang]) / np.pi, np.concatenate([np.zeros(n), np.ones(n)])])
    parts.append(Part(pts, faces, uv, nrm, np.full(len(faces), material, np.int32)))
    return merge(parts)


def cloth(width: float, height: float, material: int, folds: int = 3, amplitude: float = 0.08,
          nu: int = 16, nv: int = 24, sway: float = 0.1, seed: int = 0) -> Part:
    """A hanging banner: a sheet in the x-y plane hanging down from y=0, with vertical folds.

    ``folds`` sinusoidal folds of ``amplitude`` across the width, growing towards the bottom
    edge, plus a slight random ``sway`` of the bottom; smooth normals from the analytic surface.
    """
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi)
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    x = (s - 0.5) * width
    y = -t * height
    amp = amplitude * (0.3 + 0.7 * t)
    arg = 2 * np.pi * folds * s + phase
    z = amp * np.sin(arg) + sway * t**2
    dz_ds = amp * 2 * np.pi * folds * np.cos(arg)
    dz_dt = 0.7 * amplitude * np.sin(arg) + 2 * sway * t
    du = np.stack([np.full_like(s, width), np.zeros_like(s), dz_ds], -1)
    dv = np.stack([np.zeros_like(s), np.full_like(s, -height), dz_dt], -1)
    n = np.cross(du, dv)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    pts = np.stack([x, y, z], -1).reshape(-1, 3)
    uv = np.stack([s.ravel(), 1.0 - t.ravel()], 1)
    faces = _grid_faces(nu, nv)
    return Part(pts, faces, uv, n.reshape(-1, 3), np.full(len(faces), material, np.int32))


def leaf(length: float, width: float, material: int, bend: float = 0.3) -> Part:
    """One thin leaf along +x from the origin: a bent diamond of 4 triangles (one-sided geometry)."""
    pts = np.array([
        [0.0, 0.0, 0.0],
        [0.45 * length, 0.0, width / 2],
        [0.45 * length, 0.0, -width / 2],
        [0.5 * length, 0.0, 0.0],
        [length, 0.0, 0.0],
    ])
    pts[:, 1] -= bend * (pts[:, 0] / length) ** 2 * length
    faces = np.array([[0, 1, 3], [0, 3, 2], [3, 1, 4], [3, 4, 2]])
    uv = np.column_stack([pts[:, 0] / length, pts[:, 2] / width + 0.5])
    a, b, c = (pts[faces[:, k]] for k in range(3))
    fn = np.cross(b - a, c - a)
    nrm = np.zeros_like(pts)
    for k in range(3):
        np.add.at(nrm, faces[:, k], fn)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    return Part(pts, faces, uv, nrm, np.full(4, material, np.int32))


def plant(rng: np.random.Generator, leaf_material: int, n_leaves: int = 40, height: float = 1.0,
          leaf_length: float = 0.35, leaf_width: float = 0.06) -> Part:
    """A clump of thin leaves sprouting from the origin, arching outwards and down."""
    parts = []
    for _ in range(n_leaves):
        lf = leaf(leaf_length * rng.uniform(0.7, 1.2), leaf_width * rng.uniform(0.7, 1.3), leaf_material,
                  bend=rng.uniform(0.1, 0.5))
        tilt = rng.uniform(10, 70)
        yaw = rng.uniform(0, 360)
        h = rng.uniform(0.2, 1.0) * height
        m = translation((0, h, 0)) @ rotation((0, 1, 0), yaw) @ rotation((0, 0, 1), tilt)
        parts.append(lf.transformed(m))
    return merge(parts)


def canopy(rng: np.random.Generator, center, radii, leaf_material: int, n_leaves: int = 800,
           leaf_size: float = 0.25) -> Part:
    """Dense foliage: ``n_leaves`` small randomly oriented leaves filling an ellipsoid shell."""
    center, radii = np.asarray(center, float), np.asarray(radii, float)
    d = rng.normal(size=(n_leaves, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = rng.uniform(0.6, 1.0, n_leaves) ** (1 / 3)
    pos = center + d * r[:, None] * radii
    parts = []
    for k in range(n_leaves):
        lf = leaf(leaf_size * rng.uniform(0.6, 1.3), leaf_size * 0.45, leaf_material, bend=rng.uniform(0, 0.3))
        m = translation(pos[k]) @ rotation(rng.normal(size=3), rng.uniform(0, 360))
        parts.append(lf.transformed(m))
    return merge(parts)
