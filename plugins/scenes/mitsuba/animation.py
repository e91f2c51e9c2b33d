"""The ``animation.toml`` sidecar: keyframed camera and rigid shape motion for a Mitsuba scene.

A sidecar turns a single-frame Mitsuba scene into a sequence. It lies beside the scene file (the
folder ``--scene-dir`` names), or in a folder of its own whose ``scene`` key names the scene file
(so a read-only scene folder can be animated from elsewhere). The format (docs/scenes.md)::

    scene = "../classroom/scene.xml"   # optional: the scene file, relative to this file
    frames = 24                        # frames of the sequence (default 32)

    [camera]
    ease = "in-out"                    # default easing of each segment: linear, in, out, in-out
    [[camera.keys]]
    frame = 0                          # a key's missing fields repeat the previous key's
    position = [-1.69, 1.27, 5.89]     # (the first key's: the scene file's sensor)
    target = [-1.24, 1.19, 2.92]
    up = [0, 1, 0]
    fov = 36.0                         # vertical field of view, degrees
    [[camera.keys]]
    frame = 23
    position = [-1.2, 1.3, 4.9]
    ease = "linear"                    # easing of the segment that starts at this key

    [[shapes]]
    name = "shape12"                   # an object's name (the XML id, else shape<k>)
    pivot = [0, 0.4, 1]                # centre of rotation (default: the shape's bounding-box centre)
    [[shapes.keys]]
    frame = 0
    [[shapes.keys]]
    frame = 23
    translate = [0.5, 0, 0]            # offset from the shape's place in the file
    rotate = [0, 1, 0, 30]             # axis x, y, z and angle in degrees

Between two keys every value moves from the first key's to the second's with the eased
parameter ``e(s)`` of ``s = (t - t0) / (t1 - t0)``: positions, targets, ups, fovs and
translations linearly in ``e(s)``, rotations by spherical linear interpolation of their
quaternions. Before the first key and after the last, values hold. Without camera keys the
camera follows the generated default path (:mod:`.camera_path`); one key is a still camera.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomllib

from harness import translation

#: the sidecar's file name, looked for beside the scene file
SIDECAR = "animation.toml"
#: frames of a scene without a sidecar, or of a sidecar that gives none
DEFAULT_FRAMES = 32
EASINGS = ("linear", "in", "out", "in-out")
_TOP = {"scene", "frames", "camera", "shapes"}
_CAMERA = {"ease", "keys"}
_CAMERA_KEY = {"frame", "position", "target", "up", "fov", "ease"}
_SHAPE = {"name", "pivot", "ease", "keys"}
_SHAPE_KEY = {"frame", "translate", "rotate", "ease"}


class AnimationError(ValueError):
    """A sidecar that cannot be used; the message is one line naming the file and the problem."""


@dataclass
class CameraKey:
    frame: int
    position: np.ndarray | None = None
    target: np.ndarray | None = None
    up: np.ndarray | None = None
    fov: float | None = None
    ease: str | None = None


@dataclass
class ShapeKey:
    frame: int
    translate: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotate: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0, 0.0]))
    ease: str | None = None


@dataclass
class ShapeMotion:
    name: str
    keys: list
    pivot: np.ndarray | None = None
    ease: str = "in-out"


@dataclass
class Animation:
    """A parsed sidecar.

    Attributes
    ----------
    path : Path or None
        The sidecar (None: no sidecar, the defaults).
    frames : int
    camera_keys : list of CameraKey
        Empty: the generated default path.
    camera_ease : str
    shapes : list of ShapeMotion
    scene : Path or None
        The scene file the sidecar names (None: the one beside it).
    """

    path: Path | None = None
    frames: int = DEFAULT_FRAMES
    camera_keys: list = field(default_factory=list)
    camera_ease: str = "in-out"
    shapes: list = field(default_factory=list)
    scene: Path | None = None

    def describe(self) -> dict:
        """What the scene's ``params["animation"]`` records (JSON-able; the file by name only)."""
        return {
            "sidecar": self.path.name if self.path is not None else None,
            "frames": self.frames,
            "camera": "keyframes" if self.camera_keys else "default path",
            "camera_keys": len(self.camera_keys),
            "moving_shapes": [s.name for s in self.shapes],
        }


def sidecar_beside(folder_or_file: Path) -> Path | None:
    """The sidecar of a scene folder or file (``animation.toml`` in its folder), or None."""
    path = Path(folder_or_file)
    folder = path if path.is_dir() else path.parent
    candidate = folder / SIDECAR
    return candidate if candidate.is_file() else None


def read(path: Path | None) -> Animation:
    """Parse a sidecar (None: the defaults: :data:`DEFAULT_FRAMES` frames, the default camera path).

    Raises
    ------
    AnimationError
        One line naming the file: a TOML error, an unknown key, a value of the wrong kind.
    """
    if path is None:
        return Animation()
    path = Path(path)
    where = path.name
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise AnimationError(f"{where}: {' '.join(str(exc).split())}") from None
    _known(data, _TOP, where)
    frames = _int(data.get("frames", DEFAULT_FRAMES), f"{where}: frames", 1)
    scene = None
    if "scene" in data:
        if not isinstance(data["scene"], str) or not data["scene"].strip():
            raise AnimationError(f"{where}: scene must be the path of a scene file, got {data['scene']!r}")
        scene = Path(os.path.expandvars(os.path.expanduser(data["scene"])))
        if not scene.is_absolute():
            scene = path.parent / scene
    camera = _table(data.get("camera", {}), f"{where}: [camera]")
    _known(camera, _CAMERA, f"{where}: [camera]")
    camera_ease = _ease(camera.get("ease", "in-out"), f"{where}: camera.ease")
    keys = []
    for k, raw in enumerate(_array(camera.get("keys", []), f"{where}: camera.keys")):
        what = f"{where}: camera.keys[{k}]"
        raw = _table(raw, what)
        _known(raw, _CAMERA_KEY, what)
        if "frame" not in raw:
            raise AnimationError(f"{what}: needs a frame")
        fov = None
        if "fov" in raw:
            fov = _number(raw["fov"], f"{what}: fov")
            if not 0.0 < fov < 180.0:
                raise AnimationError(f"{what}: fov must be degrees in (0, 180), got {fov}")
        key = CameraKey(frame=_int(raw["frame"], f"{what}: frame", 0),
                        position=_vector(raw, "position", what), target=_vector(raw, "target", what),
                        up=_vector(raw, "up", what), fov=fov,
                        ease=_ease(raw["ease"], f"{what}: ease") if "ease" in raw else None)
        if key.up is not None and np.linalg.norm(key.up) == 0.0:
            raise AnimationError(f"{what}: up must not be zero")
        keys.append(key)
    _check_frames([k.frame for k in keys], frames, f"{where}: camera.keys")
    shapes = []
    seen = set()
    for n, raw in enumerate(_array(data.get("shapes", []), f"{where}: shapes")):
        what = f"{where}: shapes[{n}]"
        raw = _table(raw, what)
        _known(raw, _SHAPE, what)
        name = raw.get("name")
        if not isinstance(name, str) or not name:
            raise AnimationError(f"{what}: needs the name of a shape")
        if name in seen:
            raise AnimationError(f"{what}: shape {name!r} is animated twice")
        seen.add(name)
        ease = _ease(raw.get("ease", "in-out"), f"{what}: ease")
        shape_keys = []
        for k, kraw in enumerate(_array(raw.get("keys", []), f"{what}.keys")):
            kwhat = f"{what}.keys[{k}]"
            kraw = _table(kraw, kwhat)
            _known(kraw, _SHAPE_KEY, kwhat)
            if "frame" not in kraw:
                raise AnimationError(f"{kwhat}: needs a frame")
            previous = shape_keys[-1] if shape_keys else ShapeKey(0)
            translate = _vector(kraw, "translate", kwhat)
            rotate = _floats(kraw["rotate"], 4, f"{kwhat}: rotate") if "rotate" in kraw else None
            if rotate is not None and np.linalg.norm(rotate[:3]) == 0.0:
                raise AnimationError(f"{kwhat}: rotate needs a non-zero axis")
            shape_keys.append(ShapeKey(frame=_int(kraw["frame"], f"{kwhat}: frame", 0),
                                       translate=previous.translate if translate is None else translate,
                                       rotate=previous.rotate if rotate is None else rotate,
                                       ease=_ease(kraw["ease"], f"{kwhat}: ease") if "ease" in kraw else None))
        if not shape_keys:
            raise AnimationError(f"{what}: needs at least one key")
        _check_frames([k.frame for k in shape_keys], frames, f"{what}.keys")
        shapes.append(ShapeMotion(name=name, keys=shape_keys, pivot=_vector(raw, "pivot", what), ease=ease))
    return Animation(path=path, frames=frames, camera_keys=keys, camera_ease=camera_ease, shapes=shapes,
                     scene=scene)


def eased(s, kind: str):
    """The easing ``e(s)`` of ``s`` in [0, 1]: ``linear``, ``in`` (s^2), ``out`` (1 - (1 - s)^2) or
    ``in-out`` (smoothstep 3 s^2 - 2 s^3)."""
    s = np.clip(s, 0.0, 1.0)
    if kind == "in":
        return s * s
    if kind == "out":
        return 1.0 - (1.0 - s) * (1.0 - s)
    if kind == "in-out":
        return s * s * (3.0 - 2.0 * s)
    return s


def segments(key_frames: list[int], frames: int) -> tuple[np.ndarray, np.ndarray]:
    """For each frame: the index of the key its segment starts at and the parameter ``s`` in [0, 1].

    Frames before the first key get (0, 0), after the last (last, 0): values hold.
    """
    index = np.zeros(frames, np.int64)
    s = np.zeros(frames)
    for t in range(frames):
        k = int(np.searchsorted(key_frames, t, side="right")) - 1
        if k < 0:
            continue
        index[t] = k
        if k + 1 < len(key_frames):
            s[t] = (t - key_frames[k]) / (key_frames[k + 1] - key_frames[k])
    return index, s


def camera_rows(keys: list[CameraKey], frames: int, ease: str, start: dict) -> dict:
    """Per-frame camera arrays from keys: ``positions``, ``targets``, ``ups`` (F, 3) and ``fovs`` (F,).

    ``start`` holds the sensor's ``position``, ``target``, ``up`` and ``fov``: the values of a
    field until a key gives it.
    """
    filled = []
    current = {name: np.asarray(v, np.float64) for name, v in start.items()}
    for key in keys:
        for name in ("position", "target", "up", "fov"):
            value = getattr(key, name)
            if value is not None:
                current[name] = np.asarray(value, np.float64)
        filled.append(dict(current))
    index, s = segments([k.frame for k in keys], frames)
    rows = {name: [] for name in ("position", "target", "up", "fov")}
    for t in range(frames):
        a = filled[index[t]]
        b = filled[min(index[t] + 1, len(filled) - 1)]
        e = eased(s[t], keys[index[t]].ease or ease)
        for name in rows:
            rows[name].append((1.0 - e) * a[name] + e * b[name])
    ups = np.array(rows["up"])
    ups /= np.maximum(np.linalg.norm(ups, axis=1, keepdims=True), 1e-12)
    return {"positions": np.array(rows["position"]), "targets": np.array(rows["target"]), "ups": ups,
            "fovs": np.array(rows["fov"], np.float64).ravel()}


def shape_transforms(motion: ShapeMotion, frames: int, pivot: np.ndarray) -> np.ndarray:
    """(F, 4, 4) world-space transforms of a shape: ``T(pivot + translate) R T(-pivot)`` per frame."""
    index, s = segments([k.frame for k in motion.keys], frames)
    quats = [_quaternion(k.rotate) for k in motion.keys]
    out = np.empty((frames, 4, 4))
    for t in range(frames):
        k = index[t]
        k2 = min(k + 1, len(motion.keys) - 1)
        e = eased(s[t], motion.keys[k].ease or motion.ease)
        offset = (1.0 - e) * motion.keys[k].translate + e * motion.keys[k2].translate
        turn = np.eye(4)
        turn[:3, :3] = _rotation(_slerp(quats[k], quats[k2], e))
        out[t] = translation(pivot + offset) @ turn @ translation(-pivot)
    return out


def _quaternion(axis_angle) -> np.ndarray:
    axis = np.asarray(axis_angle[:3], np.float64)
    axis = axis / max(np.linalg.norm(axis), 1e-300)
    half = math.radians(float(axis_angle[3])) / 2.0
    return np.array([math.cos(half), *(axis * math.sin(half))])


def _slerp(a: np.ndarray, b: np.ndarray, e: float) -> np.ndarray:
    dot = float(np.dot(a, b))
    if dot < 0.0:  # the shorter way round
        b, dot = -b, -dot
    if dot > 0.9995:
        q = a + e * (b - a)
    else:
        theta = math.acos(min(dot, 1.0))
        q = (math.sin((1.0 - e) * theta) * a + math.sin(e * theta) * b) / math.sin(theta)
    return q / np.linalg.norm(q)


def _rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _known(table: dict, allowed: set, what: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise AnimationError(f"{what}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")


def _table(value, what: str) -> dict:
    if not isinstance(value, dict):
        raise AnimationError(f"{what}: must be a table, got {type(value).__name__}")
    return value


def _array(value, what: str) -> list:
    if not isinstance(value, list):
        raise AnimationError(f"{what}: must be an array of tables, got {type(value).__name__}")
    return value


def _int(value, what: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise AnimationError(f"{what} must be an integer >= {low}, got {value!r}")
    return value


def _number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise AnimationError(f"{what} must be a finite number, got {value!r}")
    return float(value)


def _floats(value, n: int, what: str) -> np.ndarray:
    if not isinstance(value, list) or len(value) != n:
        raise AnimationError(f"{what} must be {n} numbers, got {value!r}")
    return np.array([_number(v, what) for v in value], np.float64)


def _vector(table: dict, name: str, what: str) -> np.ndarray | None:
    return _floats(table[name], 3, f"{what}: {name}") if name in table else None


def _ease(value, what: str) -> str:
    if value not in EASINGS:
        raise AnimationError(f"{what} must be one of {list(EASINGS)}, got {value!r}")
    return value


def _check_frames(frames_of_keys: list[int], frames: int, what: str) -> None:
    if any(b <= a for a, b in zip(frames_of_keys, frames_of_keys[1:])):
        raise AnimationError(f"{what}: key frames must increase, got {frames_of_keys}")
    late = [f for f in frames_of_keys if f >= frames]
    if late:
        raise AnimationError(f"{what}: key frame(s) {late} past the last frame {frames - 1} (frames = {frames})")


__all__ = ["DEFAULT_FRAMES", "SIDECAR", "Animation", "AnimationError", "camera_rows", "eased", "read",
           "shape_transforms", "sidecar_beside"]
