"""Triangle meshes for the anti-aliasing scenes, built with NumPy and handed to PyVista.

A :class:`Shape` is plain arrays (points, triangles, per-point ``uv`` and ``normal``, a material
index per triangle) that are cheap to move and concatenate; :func:`polydata` turns shapes into
one ``pyvista.PolyData`` in the layout :class:`harness.SceneObject` reads (point data
``uv``/``normal``, cell data ``material``). Thin shapes (wires, balusters, blades) are the point
of these scenes: they are narrower than a pixel in places and alias without anti-aliasing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Shape:
    """Triangles with per-point uv and normal and a material index per triangle."""

    points: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    normals: np.ndarray
    material: np.ndarray

    def moved(self, matrix: np.ndarray) -> Shape:
        """The shape transformed by the 4x4 affine ``matrix`` (normals by its inverse transpose)."""
        m = np.asarray(matrix, float)
        normals = self.normals @ np.linalg.inv(m[:3, :3])
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        faces = self.faces if np.linalg.det(m[:3, :3]) > 0 else self.faces[:, ::-1]
        return Shape(self.points @ m[:3, :3].T + m[:3, 3], faces.copy(), self.uv.copy(), normals,
                     self.material.copy())


def join(shapes: list[Shape]) -> Shape:
    """One shape holding all of ``shapes``."""
    offsets = np.cumsum([0] + [len(s.points) for s in shapes[:-1]])
    return Shape(np.concatenate([s.points for s in shapes]),
                 np.concatenate([s.faces + o for s, o in zip(shapes, offsets)]),
                 np.concatenate([s.uv for s in shapes]),
                 np.concatenate([s.normals for s in shapes]),
                 np.concatenate([s.material for s in shapes]))


def polydata(shapes: Shape | list[Shape]):
    """A triangle ``pyvista.PolyData`` with point data ``uv``/``normal`` and cell data ``material``."""
    import pyvista as pv

    shape = join(shapes) if isinstance(shapes, list) else shapes
    a, b, c = (shape.points[shape.faces[:, k]] for k in range(3))
    keep = np.linalg.norm(np.cross(b - a, c - a), axis=1) > 1e-14
    faces = shape.faces[keep]
    cells = np.hstack([np.full((len(faces), 1), 3), faces]).astype(np.int64).ravel()
    mesh = pv.PolyData(shape.points.astype(np.float32), faces=cells)
    mesh.point_data["uv"] = shape.uv.astype(np.float32)
    mesh.point_data["normal"] = shape.normals.astype(np.float32)
    mesh.cell_data["material"] = shape.material[keep].astype(np.int32)
    return mesh


# ----------------------------------------------------------------------------- shapes


def _grid_faces(nu: int, nv: int) -> np.ndarray:
    """Two counter-clockwise triangles per cell of an (nu+1) x (nv+1) point grid, u-major."""
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * (nv + 1) + j).ravel()
    b = a + nv + 1
    return np.concatenate([np.stack([a, b, b + 1], 1), np.stack([a, b + 1, a + 1], 1)])


def quad(corner, edge_u, edge_v, material: int, uv_scale=(1.0, 1.0)) -> Shape:
    """The parallelogram ``corner + s edge_u + t edge_v`` (s, t in [0, 1]); normal ``edge_u x edge_v``."""
    corner, eu, ev = (np.asarray(v, float) for v in (corner, edge_u, edge_v))
    st = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]])
    points = corner + st[:, :1] * eu + st[:, 1:] * ev
    n = np.cross(eu, ev)
    n /= np.linalg.norm(n)
    return Shape(points, _grid_faces(1, 1), st * np.asarray(uv_scale, float), np.tile(n, (4, 1)),
                 np.full(2, material, np.int32))


def box(lo, hi, material: int, uv_density: float = 1.0) -> Shape:
    """An axis-aligned box with flat outward faces; uv in world units times ``uv_density``."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    sx, sy, sz = hi - lo
    x, y, z = np.eye(3)
    sides = [(lo, z * sz, y * sy, (sz, sy)), (lo + x * sx, y * sy, z * sz, (sy, sz)),
             (lo, x * sx, z * sz, (sx, sz)), (lo + y * sy, z * sz, x * sx, (sz, sx)),
             (lo, y * sy, x * sx, (sy, sx)), (lo + z * sz, x * sx, y * sy, (sx, sy))]
    return join([quad(c, u, v, material, (a * uv_density, b * uv_density)) for c, u, v, (a, b) in sides])


def tube(start, end, radius: float, material: int, segments: int = 8) -> Shape:
    """An open cylinder from ``start`` to ``end`` with smooth normals (a wire, rail or baluster)."""
    p0, p1 = np.asarray(start, float), np.asarray(end, float)
    axis = p1 - p0
    length = np.linalg.norm(axis)
    w = axis / length
    helper = np.array([0.0, 1.0, 0.0]) if abs(w[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(w, helper)
    u /= np.linalg.norm(u)
    v = np.cross(w, u)
    angle = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    ring = np.cos(angle)[:, None] * u + np.sin(angle)[:, None] * v
    points = np.concatenate([p0 + radius * ring, p1 + radius * ring])
    normals = np.concatenate([ring, ring])
    uv = np.concatenate([np.stack([angle / (2 * np.pi), np.zeros_like(angle)], 1),
                         np.stack([angle / (2 * np.pi), np.full_like(angle, length)], 1)])
    k = np.arange(segments)
    m = segments + 1
    faces = np.concatenate([np.stack([k, k + 1, k + m + 1], 1), np.stack([k, k + m + 1, k + m], 1)])
    return Shape(points, faces, uv, normals, np.full(len(faces), material, np.int32))


def sphere(radius: float, material: int, rings: int = 16, segments: int = 32) -> Shape:
    """A UV sphere at the origin with smooth outward normals."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    n = np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    uv = np.stack([p.ravel() / (2 * np.pi), 1.0 - t.ravel() / np.pi], 1)
    faces = _grid_faces(rings, segments)
    a, b, c = (n[faces[:, k]] for k in range(3))
    faces = faces[np.linalg.norm(np.cross(b - a, c - a), axis=1) > 1e-12]
    return Shape(n * radius, faces, uv, n.copy(), np.full(len(faces), material, np.int32))


def torus(major: float, minor: float, material: int, rings: int = 32, segments: int = 16) -> Shape:
    """A torus around the y axis with smooth normals (a glossy ring: curved highlights)."""
    a = np.linspace(0.0, 2.0 * np.pi, rings + 1)
    b = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    aa, bb = np.meshgrid(a, b, indexing="ij")
    centre = np.stack([np.cos(aa), np.zeros_like(aa), np.sin(aa)], -1)
    n = np.cos(bb)[..., None] * centre + np.sin(bb)[..., None] * np.array([0.0, 1.0, 0.0])
    points = (major * centre + minor * n).reshape(-1, 3)
    uv = np.stack([aa.ravel() / (2 * np.pi), bb.ravel() / (2 * np.pi)], 1)
    faces = _grid_faces(rings, segments)[:, ::-1]
    return Shape(points, faces, uv, n.reshape(-1, 3), np.full(len(faces), material, np.int32))


def blade(base, direction, width: float, bend, material: int, sections: int = 3) -> Shape:
    """A tapering two-sided blade (grass, leaf) from ``base`` along ``direction``, bent by ``bend``.

    ``direction`` gives the length and ``bend`` the sideways offset of the tip (quadratic curve);
    the blade is ``width`` wide at the base and ends in a point.
    """
    base, d, bend = (np.asarray(v, float) for v in (base, direction, bend))
    s = np.linspace(0.0, 1.0, sections + 1)
    spine = base + s[:, None] * d + (s * s)[:, None] * bend
    tangent = d + 2.0 * s[:, None] * bend
    side = np.cross(tangent, [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 * np.linalg.norm(d) else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    half = 0.5 * width * (1.0 - s)[:, None]
    left, right = spine - half * side, spine + half * side
    points = np.concatenate([left, right])
    normal = np.cross(tangent, side)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    uv = np.concatenate([np.stack([np.zeros_like(s), s], 1), np.stack([np.ones_like(s), s], 1)])
    m = sections + 1
    k = np.arange(sections)
    faces = np.concatenate([np.stack([k, k + m, k + m + 1], 1), np.stack([k, k + m + 1, k + 1], 1)])
    return Shape(points, faces, uv, np.concatenate([normal, normal]), np.full(len(faces), material, np.int32))
