"""Load a Mitsuba 0.6 / 3 XML scene folder into a :class:`harness.Scene`."""

from __future__ import annotations

import dataclasses
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from harness import Material, Scene, SceneObject

from . import animation
from .bsdfs import BsdfContext, describe, has_texture, is_glossy, material
from .emitters_sensor import camera, environment_and_sun, point_light, spot_light
from .sequence import animate
from .shapes import load_shape, sphere, to_polydata
from .sun_sky import KINDS as SUN_SKY_KINDS
from .sun_sky import sun_and_sky
from .xmlscene import MitsubaWarning, get_color, parse, version, warn

SKIPPED_QUIETLY = {"default", "integrator"}
# Mitsuba's default BSDF of an emitting shape that names none (its reflectance 0, measured against Mitsuba 3:
# docs/pathtracer.md), also the surface of the sphere standing for a point light
BLACK_BSDF = {"type": "diffuse", "reflectance": 0.0}


def find_scene_file(folder: Path) -> Path | None:
    """The Mitsuba XML of ``folder``: the file its ``animation.toml`` names (key ``scene``), else
    ``scene.xml``, else the first ``*.xml`` whose root is ``<scene>``."""
    folder = Path(folder)
    named = _sidecar_scene(folder)
    if named is not None:
        return named if named.suffix.lower() == ".xml" and _is_scene(named) else None
    if folder.is_file():
        return folder if folder.suffix.lower() == ".xml" and _is_scene(folder) else None
    if not folder.is_dir():
        return None
    preferred = folder / "scene.xml"
    if preferred.is_file() and _is_scene(preferred):
        return preferred
    candidates = [p for p in sorted(folder.glob("*.xml")) if _is_scene(p)]
    return candidates[0] if candidates else None


def _sidecar_scene(folder: Path) -> Path | None:
    """The scene file that the ``animation.toml`` of ``folder`` names, if it names one that exists."""
    sidecar = animation.sidecar_beside(folder) if folder.is_dir() else None
    if sidecar is None:
        return None
    try:
        named = animation.read(sidecar).scene
    except animation.AnimationError:
        return None  # the load reports it
    return named if named is not None and named.is_file() else None


def sidecar_of(path: Path) -> Path | None:
    """The ``animation.toml`` that animates the scene at ``path`` (a folder or an XML file): the one in
    the folder named, else the one beside the scene file; None where there is none."""
    path = Path(path)
    if path.is_dir():
        own = animation.sidecar_beside(path)
        if own is not None:
            return own
    xml_path = find_scene_file(path)
    return animation.sidecar_beside(xml_path) if xml_path is not None else None


def _is_scene(path: Path) -> bool:
    try:
        for _, element in ET.iterparse(path, events=("start",)):
            return element.tag == "scene"
    except ET.ParseError:
        return False
    return False


def load(path: Path, name: str | None = None) -> Scene:
    """Load the Mitsuba scene at ``path`` (a folder or an XML file) as a sequence.

    The ``animation.toml`` of the folder (or beside the file) gives the frames, the camera's
    keyframes and the shapes' motion (:mod:`.animation`); without one, or without camera keys,
    the camera follows the generated default path (:mod:`.camera_path`) over
    :data:`.animation.DEFAULT_FRAMES` frames. Objects are named by the shape's ``id``, else
    ``shape<k>`` with ``k`` the shape's index among the file's top-level ``<shape>`` elements;
    ``scene.params["shapes"]`` maps each object to its element.

    Unsupported elements and approximations are reported with :class:`MitsubaWarning`, and the
    distinct messages are kept in ``scene.params["approximations"]`` (for the run's manifest);
    nothing is fatal except an unreadable file. Every material's Mitsuba BSDF is described in
    ``scene.params["bsdfs"]`` (see :mod:`.bsdfs`), spot lights in ``scene.params["delta_lights"]``
    (see :func:`.emitters_sensor.spot_light`), a ``sun``/``sky``/``sunsky`` emitter's Mitsuba 3
    parameters and the model used in ``scene.params["sunsky"]`` (see :func:`.sun_sky.sun_and_sky`).
    """
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", MitsubaWarning)
        scene = _load(path, name)
    messages = []
    for item in caught:
        if issubclass(item.category, MitsubaWarning):
            text = str(item.message)
            if text not in messages:
                messages.append(text)
        warnings.warn_explicit(item.message, item.category, item.filename, item.lineno)
    scene.params["approximations"] = messages
    return scene


class _Materials:
    """The scene's materials: one per distinct (description, emission), with their descriptions."""

    def __init__(self):
        self.materials: list[Material] = []
        self.entries: list[dict] = []
        self._index: dict = {}

    def add(self, desc: dict, name: str, emission=None) -> int:
        ident = (id(desc), None if emission is None else tuple(emission))
        if ident not in self._index:
            mat = material(desc, name)
            if emission is not None:
                mat = dataclasses.replace(mat, name=f"{name}+emitter", emission=tuple(emission))
            self._index[ident] = len(self.materials)
            self.materials.append(mat)
            self.entries.append({"bsdf": desc, "one_sided_emission": emission is not None})
        return self._index[ident]


def _load(path: Path, name: str | None) -> Scene:
    xml_path = find_scene_file(Path(path))
    if xml_path is None:
        raise FileNotFoundError(f"no Mitsuba scene XML in {path}")
    folder = xml_path.parent
    sidecar = sidecar_of(Path(path))
    if name is None and sidecar is not None and sidecar.parent != folder:
        name = sidecar.parent.name  # a folder of its own animating a scene elsewhere
    root = parse(xml_path)
    ctx = BsdfContext(folder, root)
    table = _Materials()
    for node in root.findall("bsdf"):
        describe(node, ctx)
    default_bsdf = {"type": "diffuse", "reflectance": 0.5}
    objects: list[SceneObject] = []
    environment = sun = cam = None
    film = (768, 576)
    cache: dict = {}
    points = []
    delta_lights: list[dict] = []
    sunsky = None
    shapes: list[dict] = []  # object -> its element (scene.params["shapes"])
    element = -1
    for node in root:
        tag = node.tag
        if tag == "shape":
            element += 1
            mesh = load_shape(node, folder, cache)
            if mesh is None or len(mesh.corners) == 0:
                continue
            desc, label = _shape_bsdf(node, ctx)
            emission = None
            emitter = node.find("emitter")
            if desc is None:  # Mitsuba's default: diffuse 0.5, black on an emitter
                desc, label = (default_bsdf, "default") if emitter is None else (BLACK_BSDF, "emitter-default")
            if emitter is not None:
                if emitter.get("type") != "area":
                    warn(f"shape emitter {emitter.get('type')!r} treated as an area light")
                emission = get_color(emitter, "radiance", (1.0, 1.0, 1.0), illuminant=True)
            index = table.add(desc, label, emission)
            objects.append(SceneObject(node.get("id") or f"shape{element}", to_polydata(mesh, index),
                                       material=index))
            shapes.append({"object": objects[-1].name, "element": element, "id": node.get("id")})
        elif tag == "emitter" and node.get("type") == "point":
            points.append(node)
        elif tag == "emitter" and node.get("type") == "spot":
            delta_lights.append(spot_light(node))
        elif tag == "emitter" and node.get("type") in SUN_SKY_KINDS:
            env, s, sunsky = sun_and_sky(node, version(root))
            environment = env or environment
            sun = s or sun
        elif tag == "emitter":
            env, s = environment_and_sun(node, folder)
            environment = env or environment
            sun = s or sun
        elif tag == "sensor":
            cam, film = camera(node)
        elif tag in ("bsdf", "texture") or tag in SKIPPED_QUIETLY:
            continue
        else:
            warn(f"element <{tag}> is not supported and was skipped")
    if points:
        bounds = np.concatenate([np.asarray(o.mesh.points) for o in objects]) if objects else np.zeros((1, 3))
        diagonal = float(np.linalg.norm(bounds.max(axis=0) - bounds.min(axis=0)))
        for node in points:
            centre, radius, radiance = point_light(node, diagonal)
            index = table.add(BLACK_BSDF, "point-light", radiance)
            objects.append(SceneObject(node.get("id") or f"point{len(objects)}",
                                       to_polydata(sphere(centre, radius), index), material=index))
            shapes.append({"object": objects[-1].name, "element": None, "id": node.get("id"), "point_light": True})
    if cam is None:
        warn("scene has no sensor; using a camera looking at the scene's bounds")
        cam = _default_camera(objects)
    materials = table.materials
    tags = {"static", "mitsuba"}
    if any(is_glossy(e["bsdf"]) for e in table.entries):
        tags.add("glossy")
    if any(m.is_emissive for m in materials):
        tags.add("emissive")
    if any(has_texture(e["bsdf"]) for e in table.entries):
        tags.add("textured")
    if sun is not None:
        tags.add("sun")
    if delta_lights:
        tags.add("spot")
    if environment is not None:
        tags.add("sky" if environment.kind == "sky" or sunsky is not None else "environment")
    scene = Scene(
        name=name or folder.name,
        frame_count=1,
        resolution=film,
        tags=tags,
        objects=objects,
        materials=materials,
        sun=sun,
        environment=environment,
        camera=cam,
        params={"format": "mitsuba", "version": ".".join(map(str, version(root))), "file": xml_path.name,
                "film_resolution": list(film), "bsdfs": table.entries, "delta_lights": delta_lights,
                "shapes": shapes, **({"sunsky": sunsky} if sunsky is not None else {})},
        max_depth=5,
        source=str(folder),
    )
    return animate(scene, animation.read(sidecar))


def _shape_bsdf(node: ET.Element, ctx: BsdfContext) -> tuple[dict | None, str]:
    """The shape's BSDF description (inline or by reference to an id anywhere in the file) and a label."""
    inline = node.find("bsdf")
    if inline is not None:
        return describe(inline, ctx), inline.get("id") or f"{node.get('id', 'shape')}-bsdf"
    for ref in node.findall("ref"):
        target = ctx.ids.get(ref.get("id"))
        if ref.get("name") in (None, "bsdf") and target is not None and target.tag == "bsdf":
            return describe(target, ctx), ref.get("id")
        if target is None:
            warn(f"shape references unknown bsdf {ref.get('id')!r}; using the default material")
    return None, "default"


def _default_camera(objects: list):
    from harness import CameraPath

    pts = np.concatenate([np.asarray(o.mesh.points) for o in objects]) if objects else np.zeros((1, 3))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2
    eye = centre + np.array([0.0, 0.0, 1.5 * np.linalg.norm(hi - lo) + 1e-3])
    return CameraPath(positions=[eye], targets=[centre], fov=45.0)


__all__ = ["find_scene_file", "load", "sidecar_of"]
