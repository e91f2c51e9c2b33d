"""The harness's G-buffer channels from an engine's first hits (row-major arrays of the pixels).

Conventions (``harness/buffers.py``): world-space position and unit shading normal (turned to
the viewer where the back face, by winding, is seen, as the path tracer does), depth the view-space
z ``(p - eye) . forward``, and for background pixels depth ``inf``, object id -1 and zero
position, normal, albedo and emission.
"""

from __future__ import annotations

import numpy as np


def channels(hits: dict, v: dict) -> dict:
    """(H, W, ...) float32 / int32 channels from ``hits`` (see :meth:`.jit.JitEngine.first_hits`)."""
    h, w = v["height"], v["width"]
    hit = np.asarray(hits["hit"], bool)
    keep = hit[:, None]
    position = np.where(keep, hits["position"], 0.0)
    normal = np.asarray(hits["normal"], np.float64)
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    normal = np.where(keep & (length > 1e-12), normal / np.maximum(length, 1e-12), 0.0)
    depth = np.where(hit, (position - np.asarray(v["eye"])) @ np.asarray(v["forward"]), np.inf)
    out = {
        "position": position.reshape(h, w, 3),
        "normal": normal.reshape(h, w, 3),
        "albedo": np.where(keep, np.nan_to_num(hits["albedo"]), 0.0).reshape(h, w, 3),
        "emission": np.where(keep, np.nan_to_num(hits["emission"]), 0.0).reshape(h, w, 3),
        "depth": depth.reshape(h, w),
    }
    out = {k: a.astype(np.float32) for k, a in out.items()}
    out["object_id"] = np.where(hit, hits["object_id"], -1).astype(np.int32).reshape(h, w)
    return out
