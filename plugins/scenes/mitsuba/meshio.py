"""Mesh files of Mitsuba scenes: Wavefront OBJ, PLY and Mitsuba's ``.serialized`` format.

Every reader returns :class:`MeshData`: un-indexed triangles (three corners per triangle) with
optional per-corner normals and uvs, in the harness's uv convention (v = 1 at the top row of a
texture image).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class MeshData:
    """Triangles as corner arrays.

    Attributes
    ----------
    corners : ndarray (T, 3, 3) float64
    normals : ndarray (T, 3, 3) or None
    uvs : ndarray (T, 3, 2) or None
    """

    corners: np.ndarray
    normals: np.ndarray | None = None
    uvs: np.ndarray | None = None


def read_obj(path: Path, flip_tex_coords: bool = True) -> MeshData:
    """Read a Wavefront OBJ file (``v``, ``vt``, ``vn``, polygonal ``f`` fanned into triangles).

    Mitsuba flips OBJ texture coordinates by default (``flipTexCoords``), which matches the
    harness's convention; ``flip_tex_coords=False`` stores ``1 - v`` instead.
    """
    positions, texcoords, normals, faces = [], [], [], []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            if line.startswith("v "):
                positions.append(line[2:])
            elif line.startswith("vt"):
                texcoords.append(line[3:])
            elif line.startswith("vn"):
                normals.append(line[3:])
            elif line.startswith("f "):
                faces.append(line[2:].split())
    v = _table(positions, 3)
    vt = _table(texcoords, 2)
    vn = _table(normals, 3)
    idx = _face_indices(faces, (len(v), len(vt), len(vn)))  # (T, 3 corners, 3 kinds), -1 = absent
    if len(idx) == 0:
        return MeshData(np.zeros((0, 3, 3)))
    corners = v[idx[..., 0]]
    uvs = None
    if len(vt) and (idx[..., 1] >= 0).all():
        uvs = vt[idx[..., 1]]
        if not flip_tex_coords:
            uvs[..., 1] = 1.0 - uvs[..., 1]
    nrm = vn[idx[..., 2]] if len(vn) and (idx[..., 2] >= 0).all() else None
    return MeshData(corners, nrm, uvs)


def _face_indices(faces: list[list[str]], counts: tuple[int, int, int]) -> np.ndarray:
    """Zero-based (position, texcoord, normal) indices of the fanned triangles of OBJ faces."""
    if not faces:
        return np.zeros((0, 3, 3), np.int64)
    sizes = np.array([len(f) for f in faces])
    tokens = [t for f in faces for t in f]
    refs = _parse_refs(tokens)
    for k, count in enumerate(counts):
        column = refs[:, k]
        refs[:, k] = np.where(column > 0, column - 1, np.where(column < 0, count + column, -1))
    # fan every polygon (o, o + j, o + j + 1), j = 1 .. size - 2
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    fans = np.maximum(sizes - 2, 0)
    first = np.repeat(starts, fans)
    j = np.arange(fans.sum()) - np.repeat(np.cumsum(fans) - fans, fans) + 1
    corners = np.stack([first, first + j, first + j + 1], axis=1)
    return refs[corners]


def _parse_refs(tokens: list[str]) -> np.ndarray:
    """(n, 3) raw OBJ indices (0 = absent) of ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` tokens."""
    slashes = {t.count("/") for t in tokens}
    doubles = {("//" in t) for t in tokens}
    if len(slashes) == 1 and len(doubles) == 1:
        n_slash, double = slashes.pop(), doubles.pop()
        text = " ".join(tokens)
        if double:
            text = text.replace("//", " 0 ")
        values = np.array(text.replace("/", " ").split(), np.int64).reshape(len(tokens), -1)
        out = np.zeros((len(tokens), 3), np.int64)
        out[:, : values.shape[1]] = values
        if n_slash == 2 and double:
            out[:, 1] = 0
        return out
    out = np.zeros((len(tokens), 3), np.int64)
    for row, token in enumerate(tokens):
        for k, text in enumerate(token.split("/")[:3]):
            out[row, k] = int(text) if text else 0
    return out


def _table(lines: list[str], width: int) -> np.ndarray:
    if not lines:
        return np.zeros((0, width))
    rows = [row.split()[:width] for row in lines]
    return np.array([r + ["0"] * (width - len(r)) for r in rows], float)


def read_ply(path: Path) -> MeshData:
    """Read a PLY file with PyVista (uv from ``u``/``v``, ``s``/``t`` or texture coordinates)."""
    import pyvista as pv

    mesh = pv.read(str(path)).triangulate()
    faces = np.asarray(mesh.faces).reshape(-1, 4)[:, 1:]
    corners = np.asarray(mesh.points, float)[faces]
    uv = None
    data = mesh.point_data
    for a, b in (("u", "v"), ("s", "t"), ("texture_u", "texture_v")):
        if a in data and b in data:
            uv = np.stack([np.asarray(data[a]), np.asarray(data[b])], axis=1)
    if uv is None and mesh.active_texture_coordinates is not None:
        uv = np.asarray(mesh.active_texture_coordinates)
    uvs = None
    if uv is not None:
        uvs = uv[faces].astype(float)
        uvs[..., 1] = 1.0 - uvs[..., 1]
    nrm = np.asarray(mesh.point_data["Normals"], float)[faces] if "Normals" in mesh.point_data else None
    return MeshData(corners, nrm, uvs)


SERIALIZED_MAGIC = 0x041C
_HAS_NORMALS, _HAS_TEXCOORDS, _HAS_COLORS = 0x0001, 0x0002, 0x0008
_SINGLE, _DOUBLE = 0x1000, 0x2000


def read_serialized(path: Path, shape_index: int = 0) -> MeshData:
    """Read shape ``shape_index`` of a Mitsuba ``.serialized`` file (format versions 3 and 4).

    Layout (little endian): the file ends with one offset per shape (uint32 in version 3, uint64
    in version 4) and the uint32 shape count. At each offset: uint16 magic 0x041C, uint16 version,
    then a zlib stream holding uint32 flags, (version 4: a NUL-terminated name), uint64 vertex and
    triangle counts, positions, [normals], [uvs], [colours] (float32 or float64 by flag) and the
    uint32 (uint64 past 2**32 vertices) triangle indices. Mitsuba's uv origin is the top of the
    image, so ``v`` is flipped to the harness convention.
    """
    data = Path(path).read_bytes()
    count = struct.unpack_from("<I", data, len(data) - 4)[0]
    if not 0 <= shape_index < count:
        raise IndexError(f"{path}: shapeIndex {shape_index} out of range (file holds {count} shapes)")
    magic, version = struct.unpack_from("<HH", data, 0)
    if magic != SERIALIZED_MAGIC:
        raise ValueError(f"{path}: not a Mitsuba serialized mesh (magic {magic:#06x})")
    width = 8 if version >= 4 else 4
    table = np.frombuffer(data, "<u8" if width == 8 else "<u4", count, len(data) - 4 - width * count)
    start = int(table[shape_index])
    magic, version = struct.unpack_from("<HH", data, start)
    if magic != SERIALIZED_MAGIC:
        raise ValueError(f"{path}: shape {shape_index} has a bad header")
    raw = zlib.decompressobj().decompress(data[start + 4:])
    flags = struct.unpack_from("<I", raw, 0)[0]
    pos = 4
    if version >= 4:
        pos = raw.index(b"\0", pos) + 1
    nv, nt = struct.unpack_from("<QQ", raw, pos)
    pos += 16
    real = np.dtype("<f8") if flags & _DOUBLE else np.dtype("<f4")

    def take(n_values: int, dtype: np.dtype) -> np.ndarray:
        nonlocal pos
        array = np.frombuffer(raw, dtype, n_values, pos)
        pos += n_values * dtype.itemsize
        return array.astype(np.float64 if dtype.kind == "f" else np.int64)

    vertices = take(3 * nv, real).reshape(nv, 3)
    normals = take(3 * nv, real).reshape(nv, 3) if flags & _HAS_NORMALS else None
    uv = take(2 * nv, real).reshape(nv, 2) if flags & _HAS_TEXCOORDS else None
    if flags & _HAS_COLORS:
        take(3 * nv, real)
    index_type = np.dtype("<u8") if nv > 0xFFFFFFFF else np.dtype("<u4")
    faces = take(3 * nt, index_type).reshape(nt, 3)
    uvs = None
    if uv is not None:
        uvs = uv[faces]
        uvs[..., 1] = 1.0 - uvs[..., 1]
    return MeshData(vertices[faces], None if normals is None else normals[faces], uvs)


def write_serialized(path: Path, meshes: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]]) -> None:
    """Write (vertices (n, 3), faces (t, 3), uv (n, 2) or None) meshes as a version-4 ``.serialized`` file.

    Used to test :func:`read_serialized` against data whose content is known.
    """
    blobs, offsets = [], []
    position = 0
    for vertices, faces, uv in meshes:
        flags = _SINGLE | (_HAS_TEXCOORDS if uv is not None else 0)
        body = struct.pack("<I", flags) + b"mesh\0" + struct.pack("<QQ", len(vertices), len(faces))
        body += np.asarray(vertices, "<f4").tobytes()
        if uv is not None:
            body += np.asarray(uv, "<f4").tobytes()
        body += np.asarray(faces, "<u4").tobytes()
        blob = struct.pack("<HH", SERIALIZED_MAGIC, 4) + zlib.compress(body)
        offsets.append(position)
        position += len(blob)
        blobs.append(blob)
    tail = np.asarray(offsets, "<u8").tobytes() + struct.pack("<I", len(meshes))
    Path(path).write_bytes(b"".join(blobs) + tail)
