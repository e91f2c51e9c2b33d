"""Mitsuba shapes against the harness scene's objects: object ids and per-frame poses.

The Mitsuba scene plugin records which top-level ``<shape>`` element (its index among the file's
top-level shapes, in file order) each :class:`harness.SceneObject` comes from, in
``scene.params["shapes"]`` (point lights, spheres to the path tracer, come from no shape); the
renderer's copy of the file names element ``k`` ``shape_ids[k]`` (:mod:`.scenefile`). So a shape's
object is found by that record, the one mapping the scene plugin and the renderer share; a shape
the plugin skipped matches no object. The object id of a pixel is its object's index in
``scene.objects`` (so :meth:`harness.Scene.motion` moves it), and shapes without an object get ids
after those, one each: every shape has a distinct id.

A frame's pose: an object with ``transforms`` is moved by ``transform(frame)`` applied to its
rest pose, as :meth:`harness.Scene.triangles` does (mesh vertices and normals through
``mi.traverse``; the ``to_world`` of analytic shapes such as spheres and rectangles).
"""

from __future__ import annotations

import numpy as np


def match_objects(shape_ids: list[str], scene) -> dict[str, int]:
    """The harness object index of each Mitsuba shape id (-1 where the shape has no object).

    Parameters
    ----------
    shape_ids : list of str
        The ids of the file's top-level shapes, in file order.
    scene : harness.Scene
        A scene of the Mitsuba scene plugin (``scene.params["shapes"]``: ``{"object": name,
        "element": k or None, ...}`` per object).
    """
    index = {obj.name: k for k, obj in enumerate(scene.objects)}
    out = {sid: -1 for sid in shape_ids}
    for entry in scene.params.get("shapes") or ():
        element = entry.get("element")
        if element is not None and 0 <= int(element) < len(shape_ids):
            out[shape_ids[int(element)]] = index.get(entry.get("object"), -1)
    return out


def object_ids(shapes: list, matched: dict[str, int], count: int) -> dict[str, int]:
    """A distinct id per shape: its object's index, else ``count``, ``count + 1``, ... in shape order."""
    ids, extra = {}, count
    for shape in shapes:
        sid = shape.id()
        if matched.get(sid, -1) >= 0:
            ids[sid] = matched[sid]
        else:
            ids[sid] = extra
            extra += 1
    return ids


class Poser:
    """Moves the animated objects' shapes of a loaded Mitsuba scene to a frame's pose.

    Parameters
    ----------
    mi : module
        ``mitsuba`` with the scene's variant set.
    mi_scene : mitsuba.Scene
    matched : dict of str to int
        Object index per shape id (:func:`match_objects`).
    objects : list of harness.SceneObject
    """

    def __init__(self, mi, mi_scene, matched: dict[str, int], objects: list):
        self._mi = mi
        self._moving = {sid: objects[k] for sid, k in matched.items()
                        if k >= 0 and objects[k].transforms is not None}
        self._params = mi.traverse(mi_scene) if self._moving else None
        self._rest: dict[str, dict] = {}
        self._pose: dict[str, np.ndarray] = {}
        for sid in self._moving:
            self._rest[sid] = self._rest_pose(sid)
            self._pose[sid] = np.eye(4)

    @property
    def animated(self) -> bool:
        return bool(self._moving)

    def _rest_pose(self, sid: str) -> dict:
        params, rest = self._params, {}
        for name in ("vertex_positions", "vertex_normals"):
            key = f"{sid}.{name}"
            if key in params.keys() and len(params[key]) > 0:
                rest[name] = np.array(params[key], np.float64).reshape(-1, 3)
        if not rest and f"{sid}.to_world" in params.keys():
            rest["to_world"] = _matrix(params[f"{sid}.to_world"])
        return rest

    def pose(self, frame: int) -> None:
        """Put every animated shape where ``frame`` has it (no work where it is already there)."""
        if not self._moving:
            return
        mi, params, changed = self._mi, self._params, False
        for sid, obj in self._moving.items():
            m = np.asarray(obj.transform(frame), np.float64)
            if np.array_equal(m, self._pose[sid]):
                continue
            rest = self._rest[sid]
            if "vertex_positions" in rest:
                pts = rest["vertex_positions"] @ m[:3, :3].T + m[:3, 3]
                params[f"{sid}.vertex_positions"] = mi.Float(pts.astype(np.float32).ravel())
                if "vertex_normals" in rest:
                    nrm = rest["vertex_normals"] @ np.linalg.inv(m[:3, :3])
                    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
                    params[f"{sid}.vertex_normals"] = mi.Float(nrm.astype(np.float32).ravel())
            elif "to_world" in rest:
                params[f"{sid}.to_world"] = mi.Transform4f(m @ rest["to_world"])
            self._pose[sid] = m
            changed = True
        if changed:
            params.update()


def _matrix(transform) -> np.ndarray:
    """A Mitsuba (JIT or scalar) transform's 4x4 matrix as float64."""
    m = np.array(transform.matrix, np.float64)
    return m.reshape(4, 4) if m.size == 16 else m[..., 0].reshape(4, 4)
