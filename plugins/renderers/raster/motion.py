"""Motion vectors from the previous frame's camera and object transforms (Numba).

The same definition as :meth:`harness.Scene.motion` (and tested against it), computed per pixel
in one parallel pass: the surface point seen at pixel (i, j) is moved by its object's
``T(t-1) T(t)^-1`` and projected with the previous frame's unjittered camera; a background pixel
uses the point a million units along its unjittered pixel-centre ray from the previous eye.
Points behind the previous camera get zero motion.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

FAR = 1e6


@njit(cache=True, parallel=True)
def motion_kernel(position, object_id, now_to_prev, prev_view_proj, prev_eye, right, up, forward, tan_half, out):
    """Fill ``out`` (H, W, 2) with the offsets to each pixel's surface point in the previous frame."""
    height, width = object_id.shape
    aspect = width / height
    for i in prange(height):
        for j in range(width):
            oid = object_id[i, j]
            if oid >= 0:
                m = now_to_prev[oid]
                px, py, pz = position[i, j, 0], position[i, j, 1], position[i, j, 2]
                qx = m[0, 0] * px + m[0, 1] * py + m[0, 2] * pz + m[0, 3]
                qy = m[1, 0] * px + m[1, 1] * py + m[1, 2] * pz + m[1, 3]
                qz = m[2, 0] * px + m[2, 1] * py + m[2, 2] * pz + m[2, 3]
            else:
                sx = ((j + 0.5) / width * 2.0 - 1.0) * tan_half * aspect
                sy = (1.0 - (i + 0.5) / height * 2.0) * tan_half
                dx = forward[0] + sx * right[0] + sy * up[0]
                dy = forward[1] + sx * right[1] + sy * up[1]
                dz = forward[2] + sx * right[2] + sy * up[2]
                inv = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
                qx = prev_eye[0] + dx * inv * FAR
                qy = prev_eye[1] + dy * inv * FAR
                qz = prev_eye[2] + dz * inv * FAR
            v = prev_view_proj
            cw = v[3, 0] * qx + v[3, 1] * qy + v[3, 2] * qz + v[3, 3]
            if not cw > 0.0:
                out[i, j, 0] = 0.0
                out[i, j, 1] = 0.0
                continue
            cx = (v[0, 0] * qx + v[0, 1] * qy + v[0, 2] * qz + v[0, 3]) / cw
            cy = (v[1, 0] * qx + v[1, 1] * qy + v[1, 2] * qz + v[1, 3]) / cw
            out[i, j, 0] = (cx + 1.0) * 0.5 * width - 0.5 - j
            out[i, j, 1] = (1.0 - cy) * 0.5 * height - 0.5 - i


def motion_vectors(scene, position: np.ndarray, object_id: np.ndarray, frame: int) -> np.ndarray:
    """Motion (H, W, 2) float32 of ``frame`` (zero in frame 0), as :meth:`harness.Scene.motion`."""
    height, width = object_id.shape
    out = np.zeros((height, width, 2), np.float32)
    if frame == 0 or scene.camera is None:
        return out
    camera = scene.camera
    now_to_prev = np.empty((max(len(scene.objects), 1), 4, 4))
    now_to_prev[:] = np.eye(4)
    for k, obj in enumerate(scene.objects):
        if obj.transforms is not None:
            now_to_prev[k] = obj.transform(frame - 1) @ np.linalg.inv(obj.transform(frame))
    right, up, forward = camera.basis(frame)
    motion_kernel(position, object_id, now_to_prev, camera.view_projection(frame - 1, width, height),
                  camera.eye(frame - 1), right, up, forward, float(np.tan(np.radians(camera.fov_at(frame)) / 2.0)), out)
    return out
