"""Mitsuba ``<shape>`` elements as world-space triangle meshes."""

from __future__ import annotations

import struct
import xml.etree.ElementTree as ET
import zlib
from pathlib import Path

import numpy as np
import pyvista as pv

from .files import scene_file
from .meshio import MeshData, read_obj, read_ply, read_serialized
from .xmlscene import find, get_bool, get_float, get_int, transform, vector, warn


def _grid(nu: int, nv: int, f) -> MeshData:
    """Triangulated parametric patch ``f(s, t) -> (points, normals)`` over [0, 1]^2."""
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    pts, nrm = f(s, t)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a = (i * (nv + 1) + j).ravel()
    b = a + nv + 1
    faces = np.concatenate([np.stack([a, b, b + 1], 1), np.stack([a, b + 1, a + 1], 1)])
    uv = np.stack([s.ravel(), t.ravel()], 1)
    p, n = pts.reshape(-1, 3), nrm.reshape(-1, 3)
    corners = p[faces]
    area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    keep = area > 1e-14
    return MeshData(corners[keep], n[faces][keep], uv[faces][keep])


def rectangle() -> MeshData:
    """Mitsuba's rectangle: [-1, 1]^2 in the z = 0 plane, facing +z."""
    return _grid(1, 1, lambda s, t: (np.stack([2 * s - 1, 2 * t - 1, 0 * s], -1),
                                     np.broadcast_to([0.0, 0.0, 1.0], s.shape + (3,))))


def disk(segments: int = 64) -> MeshData:
    """Mitsuba's disk: the unit disk in the z = 0 plane, facing +z, scaled to the exact area pi."""
    def f(s, t):
        phi = 2 * np.pi * t
        return (np.stack([s * np.cos(phi), s * np.sin(phi), 0 * s], -1),
                np.broadcast_to([0.0, 0.0, 1.0], s.shape + (3,)))
    mesh = _grid(4, segments, f)
    c = mesh.corners
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1).sum()
    return MeshData(c * np.sqrt(np.pi / area), mesh.normals, mesh.uvs)


def sphere(center, radius: float, rings: int = 24, segments: int = 48) -> MeshData:
    """A UV sphere with outward normals, scaled so that its area is the exact sphere's ``4 pi r^2``
    (an emitting sphere then emits Mitsuba's power)."""
    def f(s, t):
        theta, phi = np.pi * s, 2 * np.pi * t
        n = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
        return n, n
    unit = _grid(rings, segments, f)
    c = unit.corners
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1).sum()
    scale = radius * np.sqrt(4.0 * np.pi / area)
    return MeshData(np.asarray(center) + scale * c, unit.normals, unit.uvs)


def cube() -> MeshData:
    """Mitsuba's cube: [-1, 1]^3 with outward faces."""
    faces = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            u, v = [(1, 2), (2, 0), (0, 1)][axis]
            if sign < 0:
                u, v = v, u

            def f(s, t, axis=axis, sign=sign, u=u, v=v):
                p = np.zeros(s.shape + (3,))
                p[..., axis] = sign
                p[..., u] = 2 * s - 1
                p[..., v] = 2 * t - 1
                n = np.zeros(s.shape + (3,))
                n[..., axis] = sign
                return p, n
            faces.append(_grid(1, 1, f))
    return MeshData(np.concatenate([m.corners for m in faces]), np.concatenate([m.normals for m in faces]),
                    np.concatenate([m.uvs for m in faces]))


def load_shape(node: ET.Element, folder: Path, serialized_cache: dict) -> MeshData | None:
    """Triangles of a ``<shape>`` element in world space, or None (warned) when unsupported.

    Mesh files are read inside the scene folder only (:func:`.files.scene_file`); a mesh file
    that holds no triangle, or that cannot be parsed, is a ``ValueError`` naming the shape and file.
    """
    kind = node.get("type")
    matrix = transform(find(node, "toWorld"))
    if kind in ("obj", "ply", "serialized"):
        mesh = _mesh_file(node, scene_file(node, folder), kind, serialized_cache)
    elif kind == "rectangle":
        mesh = rectangle()
    elif kind == "cube":
        mesh = cube()
    elif kind == "disk":
        mesh = disk()
    elif kind == "sphere":
        center_node = find(node, "center")
        center = vector(center_node) if center_node is not None else np.zeros(3)
        mesh = sphere(center, get_float(node, "radius", 1.0))
    else:
        warn(f"shape type {kind!r} is not supported and was skipped")
        return None
    normals = None if get_bool(node, "faceNormals", False) else mesh.normals
    uvs = mesh.uvs
    corners = mesh.corners @ matrix[:3, :3].T + matrix[:3, 3]
    if normals is not None:
        normals = normals @ np.linalg.inv(matrix[:3, :3])
        normals = normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-12)
    # a mirroring transform flips the winding; flipNormals flips winding and normals
    if np.linalg.det(matrix[:3, :3]) < 0:
        corners, normals, uvs = _reverse(corners), _reverse(normals), _reverse(uvs)
    if get_bool(node, "flipNormals", False):
        corners, uvs = _reverse(corners), _reverse(uvs)
        normals = None if normals is None else -_reverse(normals)
    return MeshData(corners, normals, uvs)


def _mesh_file(node: ET.Element, path: Path, kind: str, serialized_cache: dict) -> MeshData:
    """The triangles of a mesh file; an unreadable, unparseable or empty file is a ``ValueError``."""
    try:
        if kind == "obj":
            mesh = read_obj(path, get_bool(node, "flipTexCoords", True))
        elif kind == "ply":
            mesh = read_ply(path)
        else:
            index = get_int(node, "shapeIndex", 0)
            if (path, index) not in serialized_cache:
                serialized_cache[(path, index)] = read_serialized(path, index)
            mesh = serialized_cache[(path, index)]
    except (OSError, ValueError, IndexError, KeyError, struct.error, zlib.error) as exc:
        raise ValueError(f"shape {node.get('id') or kind!r}: cannot read {kind} mesh {path.name}: "
                         f"{type(exc).__name__}: {exc}") from None
    if len(mesh.corners) == 0:
        raise ValueError(f"shape {node.get('id') or kind!r}: {kind} mesh {path.name} holds no triangle "
                         "(not a mesh file?)")
    if not np.isfinite(mesh.corners).all():
        raise ValueError(f"shape {node.get('id') or kind!r}: {kind} mesh {path.name} has non-finite vertex positions")
    return mesh


def _reverse(corner_array: np.ndarray | None) -> np.ndarray | None:
    """Reverse the corner order of every triangle (None passes through)."""
    return None if corner_array is None else corner_array[:, ::-1]


def to_polydata(mesh: MeshData, material: int) -> pv.PolyData:
    """Un-indexed triangle ``PolyData`` with point data ``uv``/``normal`` and cell data ``material``."""
    count = len(mesh.corners)
    points = mesh.corners.reshape(-1, 3).astype(np.float32)
    poly = pv.PolyData.from_regular_faces(points, np.arange(3 * count).reshape(count, 3))
    uv = mesh.uvs if mesh.uvs is not None else np.zeros((count, 3, 2))
    poly.point_data["uv"] = uv.reshape(-1, 2).astype(np.float32)
    if mesh.normals is not None:
        poly.point_data["normal"] = mesh.normals.reshape(-1, 3).astype(np.float32)
    poly.cell_data["material"] = np.full(count, material, np.int32)
    return poly
