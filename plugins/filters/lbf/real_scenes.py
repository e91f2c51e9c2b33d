"""Training frames from third-party (``real`` tier) scenes: camera variants of Mitsuba XML scenes.

The registered Mitsuba scenes (``classroom``, ``living-room``, ``sponza``; read from
``../shared/scenes``) are path traced through cameras taken from their default camera path: a
random frame of the path, then a narrower field of view turned towards a random part of the
original view (a crop of it, 0.4-1x its height), at a small resolution. Light is varied by an
exposure gain on the rendered radiance (the image is linear in the emitters' strength). Inputs
are 1-spp path-traced frames, as in the benchmark, against references of
:data:`REFERENCE_SPP` samples per pixel.

All variants of one scene are the frames of one camera path on one scene object, so the path
tracer builds the scene's BVH once.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from harness import CHANNELS, CameraPath

#: real scenes whose variants train the network (and, with other cameras, select its step)
TRAIN_SCENES = ("classroom", "living-room")
#: real scenes kept out of training and step selection: they measure generalisation
HELDOUT_SCENES = ("sponza",)
#: (width, height) of the variants: a 16:9 crop and a square one
RESOLUTIONS = ((96, 54), (64, 64))
REFERENCE_SPP = 256
#: aspect ratio of the scene files' film (1280x720): crops stay inside this view
FILM_ASPECT = 16.0 / 9.0
ZOOM_RANGE = (0.4, 1.0)
EXPOSURE_RANGE = (0.5, 2.0)


class RealScenesMissing(FileNotFoundError):
    """The third-party scenes the training recipe names are not available."""


def load(reg, names) -> dict:
    """Load the registered real scenes ``names`` (their factories read ``../shared/scenes``).

    Raises
    ------
    RealScenesMissing
        One line naming the scenes missing and why, when any cannot be loaded.
    """
    if "pathtracer" not in reg.renderers:
        raise RealScenesMissing("lbf training: the real scenes need the 'pathtracer' renderer, which is not "
                                "registered; train on procedural data only with -o real=false")
    scenes, missing = {}, []
    for name in names:
        spec = reg.scenes.get(name)
        if spec is None:
            missing.append(f"{name} (no scene plugin registers it)")
            continue
        try:
            scenes[name] = spec.factory()
        except FileNotFoundError as exc:
            missing.append(f"{name} ({exc})")
    if missing:
        raise RealScenesMissing("lbf training: real scenes not found: " + "; ".join(missing)
                                + "; the shipped recipe path traces them from ../shared/scenes (train on "
                                "procedural data only with -o real=false)")
    return scenes


def variant(rng: np.random.Generator, scene_name: str, frames: int) -> dict:
    """Random camera crop, resolution, exposure and seed of one frame of a real scene."""
    return {
        "scene": scene_name,
        "frame": int(rng.integers(frames)),
        "zoom": float(rng.uniform(*ZOOM_RANGE)),
        "pan": [float(x) for x in rng.uniform(-1.0, 1.0, 2)],
        "resolution": tuple(RESOLUTIONS[int(rng.integers(len(RESOLUTIONS)))]),
        "exposure": float(math.exp(rng.uniform(*np.log(EXPOSURE_RANGE)))),
        "visibility": bool(rng.integers(2)),
        "seed": int(rng.integers(1 << 30)),
    }


def _turned(basis, yaw: float, pitch: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(right, up, forward) of the view turned by ``yaw`` about its up axis, then ``pitch`` up."""
    right, up, forward = basis
    turned = math.cos(yaw) * forward + math.sin(yaw) * right
    right = math.cos(yaw) * right - math.sin(yaw) * forward
    return right, math.cos(pitch) * up - math.sin(pitch) * turned, math.cos(pitch) * turned + math.sin(pitch) * up


def _corners_inside(basis, turned, half: float, zoomed: float) -> bool:
    """Whether the corners of the zoomed, turned 16:9 view lie inside the original one."""
    r0, u0, f0 = basis
    right, up, forward = turned
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            ray = forward + sx * zoomed * FILM_ASPECT * right + sy * zoomed * up
            depth = ray @ f0
            if depth <= 0 or abs(ray @ r0) > half * FILM_ASPECT * depth or abs(ray @ u0) > half * depth:
                return False
    return True


def variant_cameras(camera: CameraPath, variants: list[dict]) -> CameraPath:
    """One camera per variant: frame ``frame`` of ``camera``, zoomed by ``zoom`` and turned by ``pan``.

    The new view's half-height is ``zoom`` times the original's (in tangent). It turns sideways
    by ``pan[0]`` and up by ``pan[1]`` of the angles left between its half-width (half-height) and
    the original's, scaled down (bisection) until its four corners lie inside the original 16:9
    view: the variant is a crop of the view the scene file's camera path shows.
    """
    eyes, targets, ups, fovs = [], [], [], []
    for v in variants:
        t = v["frame"]
        basis = camera.basis(t)
        eye = camera.eye(t)
        distance = float(np.linalg.norm(camera.targets[min(t, len(camera.targets) - 1)] - eye))
        half = math.tan(math.radians(camera.fov_at(t)) / 2.0)
        zoomed = v["zoom"] * half
        yaw = v["pan"][0] * (math.atan(half * FILM_ASPECT) - math.atan(zoomed * FILM_ASPECT))
        pitch = v["pan"][1] * (math.atan(half) - math.atan(zoomed))
        lo, hi = 0.0, 1.0
        if not _corners_inside(basis, _turned(basis, yaw, pitch), half, zoomed):
            for _ in range(30):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if _corners_inside(basis, _turned(basis, mid * yaw, mid * pitch), half,
                                                      zoomed) else (lo, mid)
        else:
            lo = 1.0
        right, up, forward = _turned(basis, lo * yaw, lo * pitch)
        eyes.append(eye)
        targets.append(eye + max(distance, 1e-3) * forward)
        ups.append(up)
        fovs.append(math.degrees(2.0 * math.atan(zoomed)))
    return CameraPath(positions=np.array(eyes), targets=np.array(targets), up=camera.up, fov=camera.fov,
                      near=camera.near, far=camera.far, ups=np.array(ups), fovs=np.array(fovs))


def render(reg, scene, variants: list[dict]) -> list[dict[str, np.ndarray]]:
    """Path trace the variants of one scene: 1-spp frames and their references, float32 arrays.

    Returns one dict per variant with ``color``, ``variance``, ``albedo``, ``position``,
    ``normal``, ``spp``, ``ref`` and, for half of them, ``visibility``.
    """
    if not variants:
        return []
    cameras = variant_cameras(scene.camera, variants)
    posed = dataclasses.replace(scene, camera=cameras, frame_count=len(variants),
                                name=f"lbf-train-{scene.name}")
    renderer = reg.renderers["pathtracer"].factory()
    out = []
    for k, v in enumerate(variants):
        frame = renderer.render(posed, k, spp=1, seed=v["seed"], channels=frozenset(CHANNELS),
                                resolution=v["resolution"])
        ref = renderer.reference(posed, k, spp=REFERENCE_SPP, seed=v["seed"] + 1,
                                 resolution=v["resolution"])
        gain = np.float32(v["exposure"])
        names = ["albedo", "position", "normal", "spp"] + (["visibility"] if v["visibility"] else [])
        data = {name: np.array(frame[name], order="C") for name in names}
        data["color"] = np.array(frame["color"] * gain, np.float32, order="C")
        data["variance"] = np.array(frame["variance"] * (gain * gain), np.float32, order="C")
        data["ref"] = np.array(np.asarray(ref, np.float32) * gain, np.float32, order="C")
        out.append(data)
    return out


def dataset(reg, scenes: dict, seed: int, per_scene: int) -> list[dict[str, np.ndarray]]:
    """``per_scene`` rendered variants of each scene in ``scenes`` (name -> loaded scene), in order."""
    rng = np.random.default_rng(seed)
    out = []
    for name, scene in scenes.items():
        frames = len(scene.camera.positions)
        out += render(reg, scene, [variant(rng, name, frames) for _ in range(per_scene)])
    return out
