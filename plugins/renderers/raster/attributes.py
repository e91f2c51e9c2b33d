"""Exact float G-buffer attributes from a visibility buffer.

For every covered pixel the primary ray of :meth:`harness.CameraPath.primary_rays` is intersected
in float64 with the triangle the rasterizer found there (Moller-Trumbore); position, depth,
interpolated shading normal, uv and textured albedo follow from the hit. Nothing passes through
an 8-bit target, so the values are float32 roundings of float64 results.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, parallel=True)
def surface_kernel(tri_ids, vertices, normals, uvs, eye, right, up, forward, tan_half, jitter_x, jitter_y,
                   position, normal, uv, depth, direction):
    """Fill ``position``, ``normal``, ``uv`` and ``depth`` for every pixel with ``tri_ids >= 0``.

    ``direction`` receives the unit primary-ray direction of every pixel (background included).
    The shading normal is interpolated from the corner normals and turned to the side of the
    surface the ray arrives from (two-sided surfaces); barycentrics are clamped to the triangle
    for interpolation, while the position is the exact ray-plane hit.
    """
    height, width = tri_ids.shape
    aspect = width / height
    for i in prange(height):
        sy = (1.0 - (i + 0.5 + jitter_y) / height * 2.0) * tan_half
        for j in range(width):
            sx = ((j + 0.5 + jitter_x) / width * 2.0 - 1.0) * tan_half * aspect
            dx = forward[0] + sx * right[0] + sy * up[0]
            dy = forward[1] + sx * right[1] + sy * up[1]
            dz = forward[2] + sx * right[2] + sy * up[2]
            inv = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
            dx *= inv
            dy *= inv
            dz *= inv
            direction[i, j, 0] = dx
            direction[i, j, 1] = dy
            direction[i, j, 2] = dz
            t_id = tri_ids[i, j]
            if t_id < 0:
                continue
            v0x, v0y, v0z = vertices[t_id, 0, 0], vertices[t_id, 0, 1], vertices[t_id, 0, 2]
            e1x = vertices[t_id, 1, 0] - v0x
            e1y = vertices[t_id, 1, 1] - v0y
            e1z = vertices[t_id, 1, 2] - v0z
            e2x = vertices[t_id, 2, 0] - v0x
            e2y = vertices[t_id, 2, 1] - v0y
            e2z = vertices[t_id, 2, 2] - v0z
            px = dy * e2z - dz * e2y
            py = dz * e2x - dx * e2z
            pz = dx * e2y - dy * e2x
            det = e1x * px + e1y * py + e1z * pz
            if abs(det) < 1e-300:
                tri_ids[i, j] = -1
                continue
            inv_det = 1.0 / det
            tx, ty, tz = eye[0] - v0x, eye[1] - v0y, eye[2] - v0z
            b1 = (tx * px + ty * py + tz * pz) * inv_det
            qx = ty * e1z - tz * e1y
            qy = tz * e1x - tx * e1z
            qz = tx * e1y - ty * e1x
            b2 = (dx * qx + dy * qy + dz * qz) * inv_det
            dist = (e2x * qx + e2y * qy + e2z * qz) * inv_det
            hx, hy, hz = eye[0] + dist * dx, eye[1] + dist * dy, eye[2] + dist * dz
            position[i, j, 0] = hx
            position[i, j, 1] = hy
            position[i, j, 2] = hz
            depth[i, j] = (hx - eye[0]) * forward[0] + (hy - eye[1]) * forward[1] + (hz - eye[2]) * forward[2]
            # barycentrics clamped onto the triangle for attribute interpolation
            b1 = min(max(b1, 0.0), 1.0)
            b2 = min(max(b2, 0.0), 1.0)
            s = b1 + b2
            if s > 1.0:
                b1 /= s
                b2 /= s
            b0 = 1.0 - b1 - b2
            nx = b0 * normals[t_id, 0, 0] + b1 * normals[t_id, 1, 0] + b2 * normals[t_id, 2, 0]
            ny = b0 * normals[t_id, 0, 1] + b1 * normals[t_id, 1, 1] + b2 * normals[t_id, 2, 1]
            nz = b0 * normals[t_id, 0, 2] + b1 * normals[t_id, 1, 2] + b2 * normals[t_id, 2, 2]
            gx = e1y * e2z - e1z * e2y
            gy = e1z * e2x - e1x * e2z
            gz = e1x * e2y - e1y * e2x
            length = np.sqrt(nx * nx + ny * ny + nz * nz)
            if length < 1e-12:
                nx, ny, nz = gx, gy, gz
                length = np.sqrt(nx * nx + ny * ny + nz * nz)
            nx /= length
            ny /= length
            nz /= length
            if gx * dx + gy * dy + gz * dz > 0.0:  # back face seen: turn the normal to the viewer
                nx, ny, nz = -nx, -ny, -nz
            normal[i, j, 0] = nx
            normal[i, j, 1] = ny
            normal[i, j, 2] = nz
            uv[i, j, 0] = b0 * uvs[t_id, 0, 0] + b1 * uvs[t_id, 1, 0] + b2 * uvs[t_id, 2, 0]
            uv[i, j, 1] = b0 * uvs[t_id, 0, 1] + b1 * uvs[t_id, 1, 1] + b2 * uvs[t_id, 2, 1]


@njit(cache=True, parallel=True)
def texture_kernel(material, uv, base, tex_data, tex_offset, tex_height, tex_width, out):
    """``out = base[material] * bilinear(texture[material], uv)`` (repeat wrap; 1 where untextured).

    Texture ``m`` is stored row-major (row 0 = top, v = 1) in ``tex_data`` from ``tex_offset[m]``
    with ``tex_height[m] x tex_width[m]`` texels of 3 channels; texel (r, c) is centred at
    ``u = (c + 0.5) / w``, ``v = 1 - (r + 0.5) / h``.
    """
    height, width = material.shape
    for i in prange(height):
        for j in range(width):
            m = material[i, j]
            if m < 0:
                continue
            th = tex_height[m]
            tw = tex_width[m]
            for c in range(3):
                out[i, j, c] = base[m, c]
            if th == 0:
                continue
            x = uv[i, j, 0] * tw - 0.5
            y = (1.0 - uv[i, j, 1]) * th - 0.5
            x0 = np.floor(x)
            y0 = np.floor(y)
            fx = x - x0
            fy = y - y0
            c0 = int(x0) % tw
            r0 = int(y0) % th
            c1 = (c0 + 1) % tw
            r1 = (r0 + 1) % th
            off = tex_offset[m]
            for c in range(3):
                t00 = tex_data[off + (r0 * tw + c0) * 3 + c]
                t01 = tex_data[off + (r0 * tw + c1) * 3 + c]
                t10 = tex_data[off + (r1 * tw + c0) * 3 + c]
                t11 = tex_data[off + (r1 * tw + c1) * 3 + c]
                value = (t00 * (1 - fx) + t01 * fx) * (1 - fy) + (t10 * (1 - fx) + t11 * fx) * fy
                out[i, j, c] = base[m, c] * value


class TextureTable:
    """All albedo textures of a scene packed for :func:`texture_kernel`.

    Parameters
    ----------
    materials : list of harness.Material
    """

    def __init__(self, materials):
        arrays = [m.texture_array() for m in materials]
        self.base = np.array([_base_albedo(m) for m in materials] or [[0.0, 0.0, 0.0]], np.float32)
        self.height = np.array([0 if a is None else a.shape[0] for a in arrays] or [0], np.int64)
        self.width = np.array([0 if a is None else a.shape[1] for a in arrays] or [0], np.int64)
        sizes = [0 if a is None else a.size for a in arrays]
        self.offset = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64) if sizes else np.zeros(1, np.int64)
        flat = [a.ravel() for a in arrays if a is not None]
        self.data = np.concatenate(flat).astype(np.float32) if flat else np.zeros(1, np.float32)

    def albedo(self, material: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Textured albedo (H, W, 3) float32 for material indices (-1 = background, zero)."""
        out = np.zeros(material.shape + (3,), np.float32)
        texture_kernel(material, uv, self.base, self.data, self.offset, self.height, self.width, out)
        return out


def _base_albedo(material) -> tuple:
    """The colour the albedo channel reports for a material before texturing.

    Diffuse and plastic: the diffuse albedo; conductor and mirror: the specular reflectance F0;
    dielectric: white (it passes or reflects all light).
    """
    if material.kind in ("conductor", "mirror"):
        return material.specular
    if material.kind == "dielectric":
        return (1.0, 1.0, 1.0)
    return material.albedo
