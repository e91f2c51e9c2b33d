"""A loaded single-frame Mitsuba scene made a sequence: its camera path and moving shapes per frame."""

from __future__ import annotations

import dataclasses

import numpy as np

from harness import CameraPath, Scene

from .animation import Animation, AnimationError, camera_rows, shape_transforms
from .camera_path import check_inside, crossings, default_path, scene_bounds
from .xmlscene import warn


def animate(scene: Scene, animation: Animation) -> Scene:
    """``scene`` (one frame, static objects) as the sequence ``animation`` describes.

    The camera is a :class:`harness.CameraPath` with one row per frame (positions, targets, and
    per-frame ups and fovs where they change); each moving shape's object gets ``transforms``
    (F, 4, 4), applied to its world-space mesh. ``scene.params["animation"]`` records what was
    used (the default path's dolly and pan included).

    Raises
    ------
    AnimationError
        A camera path that leaves the scene bounds (:func:`.camera_path.check_inside`), a shape
        name that names no object or several.
    """
    frames = animation.frames
    where = animation.path.name if animation.path is not None else f"scene {scene.name!r}"
    cam = scene.camera
    soup = scene.triangles(0)
    low, high = scene_bounds(soup.vertices, cam.eye(0))
    record = animation.describe()
    ups = fovs = None
    if animation.camera_keys:
        start = {"position": cam.eye(0), "target": cam.targets[0], "up": cam.up_at(0), "fov": cam.fov_at(0)}
        rows = camera_rows(animation.camera_keys, frames, animation.camera_ease, start)
        check_inside(rows["positions"], low, high, where)
        crossed = crossings(rows["positions"], soup.vertices)
        if crossed:
            warn(f"{where}: the camera passes through a surface between frames {crossed[0] - 1} and {crossed[0]}"
                 + (f" (and {len(crossed) - 1} more moves)" if len(crossed) > 1 else ""))
        if np.ptp(rows["ups"], axis=0).max() > 0.0:
            ups = rows["ups"]
        if np.ptp(rows["fovs"]) > 0.0:
            fovs = rows["fovs"]
        up, fov = tuple(float(v) for v in rows["ups"][0]), float(rows["fovs"][0])
    else:
        w, h = scene.resolution
        rows = default_path(soup.vertices, cam, frames, w / h)
        check_inside(rows["positions"], low, high, where)
        record["default_path"] = {"dolly": rows["dolly"], "direction": rows["direction"], "pan_degrees": rows["pan"]}
        up, fov = cam.up, cam.fov
    camera = CameraPath(positions=rows["positions"], targets=rows["targets"], up=up, fov=fov, near=cam.near,
                        far=cam.far, ups=ups, fovs=fovs)
    objects = list(scene.objects)
    names = [o.name for o in objects]
    for motion in animation.shapes:
        matches = [k for k, n in enumerate(names) if n == motion.name]
        if len(matches) != 1:
            shown = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
            problem = "names no object" if not matches else f"names {len(matches)} objects"
            raise AnimationError(f"{where}: shape {motion.name!r} {problem}; the scene's shapes: {shown}")
        k = matches[0]
        points = np.asarray(objects[k].mesh.points, np.float64)
        pivot = motion.pivot if motion.pivot is not None else (points.min(axis=0) + points.max(axis=0)) / 2.0
        objects[k] = dataclasses.replace(objects[k], transforms=shape_transforms(motion, frames, pivot))
    tags = set(scene.tags) - {"static", "dynamic"}
    tags.add("dynamic" if frames > 1 else "static")
    if animation.shapes:
        tags.add("moving_objects")
    params = {**scene.params, "animation": record}
    return dataclasses.replace(scene, frame_count=frames, camera=camera, objects=objects, tags=tags, params=params)


__all__ = ["animate"]
