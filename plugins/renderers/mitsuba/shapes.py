"""Mitsuba shapes against the harness scene's objects: object ids and per-frame poses.

The Mitsuba scene plugin makes one :class:`harness.SceneObject` per top-level ``<shape>`` it can
read, in file order (then one sphere per ``point`` emitter, which Mitsuba renders as a point
light and not as a shape). So the file's shapes and the scene's objects are walked together: a
shape is the next object when their bounding boxes agree (the plugin bakes ``toWorld`` into the
points; a tolerance of 2% of the object's diagonal covers the area-preserving scale of its
tessellated spheres; a mesh's box is that of the vertices its faces use); a shape the plugin skipped
matches no object. The object id of a pixel is
its object's index in ``scene.objects`` (so :meth:`harness.Scene.motion` moves it), and shapes
without an object get ids after those, one each: every shape has a distinct id.

A frame's pose: an object with ``transforms`` is moved by ``transform(frame)`` applied to its
rest pose, as :meth:`harness.Scene.triangles` does (mesh vertices and normals through
``mi.traverse``; the ``to_world`` of analytic shapes such as spheres and rectangles).
"""

from __future__ import annotations

import numpy as np

#: bounding boxes agree within this fraction of the object's diagonal (plus a scene-size floor)
BOX_TOLERANCE = 0.02


def match_objects(shapes: dict, shape_ids: list[str], objects: list) -> dict[str, int]:
    """The harness object index of each Mitsuba shape id (file order walk; -1 where none matches).

    Parameters
    ----------
    shapes : dict of str to mitsuba Shape
        The loaded scene's shapes by id.
    shape_ids : list of str
        The file's top-level shape ids, in file order.
    objects : list of harness.SceneObject
    """
    boxes = [_object_box(o) for o in objects]
    corners = [b for b in boxes if b is not None]
    if corners:
        allpts = np.concatenate(corners)
        floor = 1e-5 * float(np.linalg.norm(allpts.max(0) - allpts.min(0)))
    else:
        floor = 0.0
    out, at = {}, 0
    for sid in shape_ids:
        shape = shapes.get(sid)
        if shape is None:
            continue
        lo, hi = shape_box(shape)
        if at < len(objects) and boxes[at] is not None and _same_box(boxes[at], lo, hi, floor):
            out[sid] = at
            at += 1
        else:
            out[sid] = -1
    return out


def shape_box(shape) -> tuple[np.ndarray, np.ndarray]:
    """A shape's world bounding box: of the vertices its faces use, for a mesh (Mitsuba's own box of
    an OBJ mesh also holds vertices no face uses), else ``shape.bbox()``."""
    if shape.is_mesh():
        faces = np.array(shape.faces_buffer(), np.int64).ravel()
        points = np.array(shape.vertex_positions_buffer(), np.float64).reshape(-1, 3)
        if faces.size:
            used = points[np.unique(faces)]
            return used.min(0), used.max(0)
    box = shape.bbox()
    return np.array(box.min, np.float64).ravel(), np.array(box.max, np.float64).ravel()


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


def _object_box(obj) -> np.ndarray | None:
    pts = np.asarray(obj.mesh.points, np.float64)
    if pts.size == 0:
        return None
    return np.stack([pts.min(0), pts.max(0)])


def _same_box(box: np.ndarray, lo: np.ndarray, hi: np.ndarray, floor: float) -> bool:
    tol = BOX_TOLERANCE * float(np.linalg.norm(box[1] - box[0])) + floor
    return bool(np.all(np.abs(box[0] - lo) <= tol) and np.all(np.abs(box[1] - hi) <= tol))


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
