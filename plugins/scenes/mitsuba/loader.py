"""Load a Mitsuba 0.6 / 3 XML scene folder into a :class:`harness.Scene`."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from harness import Material, Scene, SceneObject

from .bsdfs import BsdfContext, convert, with_emission
from .emitters_sensor import camera, environment_and_sun
from .shapes import load_shape, to_polydata
from .xmlscene import get_color, parse, version, warn

SKIPPED_QUIETLY = {"default", "integrator"}


def find_scene_file(folder: Path) -> Path | None:
    """The Mitsuba XML of ``folder`` (``scene.xml`` first, else the only ``*.xml`` whose root is ``<scene>``)."""
    folder = Path(folder)
    if folder.is_file():
        return folder if folder.suffix.lower() == ".xml" and _is_scene(folder) else None
    if not folder.is_dir():
        return None
    preferred = folder / "scene.xml"
    if preferred.is_file() and _is_scene(preferred):
        return preferred
    candidates = [p for p in sorted(folder.glob("*.xml")) if _is_scene(p)]
    return candidates[0] if candidates else None


def _is_scene(path: Path) -> bool:
    try:
        for _, element in ET.iterparse(path, events=("start",)):
            return element.tag == "scene"
    except ET.ParseError:
        return False
    return False


def load(path: Path, name: str | None = None) -> Scene:
    """Load the Mitsuba scene at ``path`` (a folder or an XML file).

    Unsupported elements and approximations are reported with :class:`MitsubaWarning`; nothing
    is fatal except an unreadable file.
    """
    xml_path = find_scene_file(Path(path))
    if xml_path is None:
        raise FileNotFoundError(f"no Mitsuba scene XML in {path}")
    folder = xml_path.parent
    root = parse(xml_path)
    textures = {t.get("id"): t for t in root.findall("texture") if t.get("id")}
    ctx = BsdfContext(folder, textures)
    materials: list[Material] = []
    named: dict[str, int] = {}
    for node in root.findall("bsdf"):
        ident = node.get("id") or f"bsdf{len(materials)}"
        named[ident] = len(materials)
        materials.append(convert(node, ident, ctx))
    default_material = None
    objects: list[SceneObject] = []
    environment = sun = cam = None
    film = (768, 576)
    cache: dict = {}
    for node in root:
        tag = node.tag
        if tag == "shape":
            mesh = load_shape(node, folder, cache)
            if mesh is None or len(mesh.corners) == 0:
                continue
            index = _shape_material(node, named, materials, ctx)
            if index is None:
                if default_material is None:
                    default_material = len(materials)
                    materials.append(Material("default", albedo=(0.5, 0.5, 0.5)))
                index = default_material
            emitter = node.find("emitter")
            if emitter is not None:
                if emitter.get("type") != "area":
                    warn(f"shape emitter {emitter.get('type')!r} treated as an area light")
                radiance = get_color(emitter, "radiance", (1.0, 1.0, 1.0))
                materials.append(with_emission(materials[index], radiance, f"{materials[index].name}+emitter"))
                index = len(materials) - 1
            objects.append(SceneObject(node.get("id") or f"shape{len(objects)}", to_polydata(mesh, index),
                                       material=index))
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
    if cam is None:
        warn("scene has no sensor; using a camera looking at the scene's bounds")
        cam = _default_camera(objects)
    glossy = any(m.kind in ("conductor", "mirror", "dielectric") or (m.kind == "plastic" and m.roughness < 0.3)
                 for m in materials)
    tags = {"static", "mitsuba"}
    if glossy:
        tags.add("glossy")
    if any(m.is_emissive for m in materials):
        tags.add("emissive")
    if any(m.texture is not None for m in materials):
        tags.add("textured")
    if sun is not None:
        tags.add("sun")
    if environment is not None:
        tags.add("sky" if environment.kind == "sky" else "environment")
    return Scene(
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
                "film_resolution": list(film)},
        max_depth=5,
        source=str(folder),
    )


def _shape_material(node: ET.Element, named: dict, materials: list, ctx: BsdfContext) -> int | None:
    inline = node.find("bsdf")
    if inline is not None:
        materials.append(convert(inline, inline.get("id") or f"{node.get('id', 'shape')}-bsdf", ctx))
        return len(materials) - 1
    for ref in node.findall("ref"):
        if ref.get("name") in (None, "bsdf") and ref.get("id") in named:
            return named[ref.get("id")]
        if ref.get("id") not in named:
            warn(f"shape references unknown bsdf {ref.get('id')!r}; using the default material")
    return None


def _default_camera(objects: list):
    from harness import CameraPath

    pts = np.concatenate([np.asarray(o.mesh.points) for o in objects]) if objects else np.zeros((1, 3))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = (lo + hi) / 2
    eye = centre + np.array([0.0, 0.0, 1.5 * np.linalg.norm(hi - lo) + 1e-3])
    return CameraPath(positions=[eye], targets=[centre], fov=45.0)


__all__ = ["find_scene_file", "load"]
