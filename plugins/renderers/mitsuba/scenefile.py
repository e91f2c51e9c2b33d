"""The Mitsuba scene file of a harness scene, adapted so that Mitsuba 3 loads it.

A scene built by the Mitsuba scene plugin records its folder in ``scene.source`` and the XML's
file name in ``scene.params["file"]`` (``scene.params["format"] == "mitsuba"``). Mitsuba 3 reads
0.6 files itself (it upgrades camelCase names); what it refuses is adapted here, each change
reported once as a warning:

* ``<integrator>`` and ``<sensor>`` are removed (the renderer brings its own, per frame);
* ``roughdiffuse`` (Oren-Nayar, not in Mitsuba 3) becomes ``diffuse``;
* ``phong`` (not in Mitsuba 3) becomes the ``roughplastic`` the scene plugin approximates it by
  (Beckmann ``alpha = sqrt(2 / (exponent + 2))``, specular reflectance 0.2 unless given);
* a 0.6 file's ``sun``/``sky``/``sunsky`` emitter (a date-and-place model Mitsuba 3 lacks) becomes
  Mitsuba 3's ``sunsky`` with the parameters the scene plugin read (``scene.params["sunsky"]``,
  Mitsuba 3's semantics), the same light the path tracer renders;
* texture filters other than ``nearest``/``bilinear`` (0.6's ``trilinear``, ``ewa``) become
  ``bilinear``;
* properties Mitsuba 3 reports as unreferenced (``extEta`` of ``roughconductor``, ...) are
  dropped, one load attempt per error message.

Files the scene names (``filename`` properties, ``<include>``) must lie inside the scene's folder
once resolved, as for the scene plugin (a scene file is untrusted input), unless the environment
variable :data:`ALLOW_ENV` is ``1``.

Every top-level ``<shape>`` without an ``id`` gets ``harness_shape_<k>`` (``k``: its position
among the top-level shapes), so that shapes can be found by name in the loaded scene and in
``mi.traverse``.
"""

from __future__ import annotations

import math
import os
import re
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

OWNER = "renderer 'mitsuba'"
#: prefix of the ids given to unnamed top-level shapes
SHAPE_ID = "harness_shape_"
#: load attempts (each drops the properties one error names)
ATTEMPTS = 50
#: Mitsuba 0.6's sun and sky emitters
SUN_SKY = ("sun", "sky", "sunsky")
#: set to ``1`` to let scene files name files outside their folder (the scene plugin's variable)
ALLOW_ENV = "DENOISE_HARNESS_ALLOW_OUTSIDE_FILES"


class MitsubaAdaptation(UserWarning):
    """A part of a scene file was changed so that Mitsuba 3 loads it."""


def scene_file(scene) -> Path:
    """The Mitsuba XML a harness scene was loaded from.

    Raises
    ------
    ValueError
        The scene does not come from a Mitsuba XML (one line naming it), or the file is gone.
    """
    params = getattr(scene, "params", None) or {}
    if scene.kind != "mesh" or params.get("format") != "mitsuba" or not params.get("file"):
        raise ValueError(f"{OWNER}: renders scenes loaded from a Mitsuba XML file (--scene-dir FOLDER, or the "
                         f"classroom / living-room / sponza scenes); {scene.name!r} is not one")
    path = Path(scene.source) / str(params["file"])
    if not path.is_file():
        raise ValueError(f"{OWNER}: the scene file of {scene.name!r} is missing: {path}")
    return path.resolve()


def adapted_xml(path: Path, sunsky: dict | None = None) -> tuple[ET.Element, list[str]]:
    """The scene file as Mitsuba 3 takes it, and the ids of its top-level shapes in file order.

    Parameters
    ----------
    path : Path
    sunsky : dict, optional
        ``scene.params["sunsky"]`` of the scene plugin (Mitsuba 3 ``sunsky`` parameters).
    """
    root = ET.parse(path).getroot()
    _check_files(root, path)
    old = _version(root) < (3,)
    for tag in ("integrator", "sensor"):
        for node in root.findall(tag):
            root.remove(node)
    notes = []
    for bsdf in root.iter("bsdf"):
        if bsdf.get("type") == "phong":
            exponent = next((float(p.get("value")) for p in bsdf if _snake(p.get("name") or "") == "exponent"), 30.0)
            for prop in [p for p in bsdf if _snake(p.get("name") or "") == "exponent"]:
                bsdf.remove(prop)
            bsdf.set("type", "roughplastic")
            if not any(_snake(p.get("name") or "") == "specular_reflectance" for p in bsdf):
                ET.SubElement(bsdf, "float", name="specularReflectance" if old else "specular_reflectance",
                              value="0.2")
            ET.SubElement(bsdf, "float", name="alpha", value=repr(math.sqrt(2.0 / (exponent + 2.0))))
            ET.SubElement(bsdf, "string", name="distribution", value="beckmann")
            notes.append("phong is not in Mitsuba 3: rendered as the scene plugin's roughplastic approximation")
    if old:
        for node in [n for n in root.findall("emitter") if n.get("type") in SUN_SKY]:
            root.remove(node)
            notes.append(f"Mitsuba 0.6's {node.get('type')} emitter: Mitsuba 3's sunsky of the parameters the scene "
                         "plugin read")
        if sunsky is not None and any(n.startswith("Mitsuba 0.6's") for n in notes):
            root.append(_sunsky(sunsky))
    for bsdf in root.iter("bsdf"):
        if bsdf.get("type") == "roughdiffuse":
            notes.append("roughdiffuse (Oren-Nayar) is not in Mitsuba 3: rendered as diffuse")
            bsdf.set("type", "diffuse")
            for prop in [p for p in bsdf if _snake(p.get("name") or "") in ("alpha", "distribution")]:
                bsdf.remove(prop)
    for texture in root.iter("texture"):
        for prop in texture:
            if _snake(prop.get("name") or "") == "filter_type" and prop.get("value") not in ("nearest", "bilinear"):
                notes.append(f"texture filter {prop.get('value')!r} is not in Mitsuba 3: bilinear")
                prop.set("value", "bilinear")
    taken = {node.get("id") for node in root.iter() if node.get("id")}
    ids = []
    for k, node in enumerate(root.findall("shape")):
        if not node.get("id"):
            name = f"{SHAPE_ID}{k}"
            while name in taken:
                name += "_"
            node.set("id", name)
            taken.add(name)
        ids.append(node.get("id"))
    for note in dict.fromkeys(notes):
        warnings.warn(f"{OWNER}: {path.name}: {note}", MitsubaAdaptation, stacklevel=3)
    return root, ids


def load(mi, path: Path, sunsky: dict | None = None):
    """Load the adapted scene file (:func:`adapted_xml`) with the current Mitsuba variant.

    Returns
    -------
    (mitsuba.Scene, list of str)
        The scene and its top-level shape ids in file order.
    """
    root, ids = adapted_xml(path, sunsky)
    resolver = mi.file_resolver()
    saved = [str(p) for p in resolver]
    resolver.prepend(str(path.parent))
    try:
        for _ in range(ATTEMPTS):
            try:
                return mi.load_string(ET.tostring(root, encoding="unicode"), optimize=False), ids
            except RuntimeError as exc:
                dropped = _drop_unreferenced(root, str(exc))
                if not dropped:
                    raise ValueError(f"{OWNER}: Mitsuba 3 cannot load {path}: {_first_line(exc)}") from exc
                warnings.warn(f"{OWNER}: {path.name}: dropped {dropped} (not used by Mitsuba 3)",
                              MitsubaAdaptation, stacklevel=2)
    finally:
        resolver.clear()
        for folder in saved:
            resolver.append(folder)
    raise ValueError(f"{OWNER}: Mitsuba 3 cannot load {path} after {ATTEMPTS} adaptations")


def _check_files(root: ET.Element, path: Path) -> None:
    """Refuse a file name that leads outside the scene's folder (unless :data:`ALLOW_ENV` is ``1``)."""
    if os.environ.get(ALLOW_ENV, "") == "1":
        return
    folder = path.parent.resolve()
    defaults = {d.get("name"): d.get("value") or "" for d in root.findall("default")}
    for node in root.iter():
        if node.tag == "include":
            name = node.get("filename")
        elif node.tag == "string" and _snake(node.get("name") or "") == "filename":
            name = node.get("value")
        else:
            continue
        if not name:
            continue
        name = re.sub(r"\$(\w+)", lambda m: defaults.get(m.group(1), m.group(0)), name)
        target = (folder / name).resolve()
        if target != folder and folder not in target.parents:
            raise ValueError(f"{OWNER}: {path.name} names {name!r}, which is outside the scene folder {folder} "
                             f"(set {ALLOW_ENV}=1 to allow files outside it)")


def _version(root: ET.Element) -> tuple[int, ...]:
    return tuple(int(p) for p in re.findall(r"\d+", root.get("version", "0.6.0"))) or (0, 6, 0)


def _sunsky(record: dict) -> ET.Element:
    """Mitsuba 3's ``sunsky`` element of a ``scene.params["sunsky"]`` record."""
    node = ET.Element("emitter", type="sunsky")
    x, y, z = (repr(float(v)) for v in record["sun_direction"])
    ET.SubElement(node, "vector", name="sun_direction", x=x, y=y, z=z)
    albedo = [float(v) for v in np.broadcast_to(record["albedo"], 3)]
    ET.SubElement(node, "rgb", name="albedo", value=", ".join(map(repr, albedo)))
    for name in ("turbidity", "sky_scale", "sun_scale", "sun_aperture"):
        ET.SubElement(node, "float", name=name, value=repr(float(record[name])))
    ET.SubElement(node, "boolean", name="complex_sun", value=str(bool(record["complex_sun"])).lower())
    m = np.eye(4)
    m[:3, :3] = np.asarray(record["to_world"], float)
    transform = ET.SubElement(node, "transform", name="to_world")
    ET.SubElement(transform, "matrix", value=" ".join(repr(float(v)) for v in m.ravel()))
    return node


def _snake(name: str) -> str:
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


def _first_line(exc: Exception) -> str:
    text = str(exc).strip().splitlines()
    return text[-1] if text else type(exc).__name__


def _drop_unreferenced(root: ET.Element, message: str) -> str:
    """Remove the properties a load error names as unreferenced; what was dropped, or ''."""
    plugin = re.search(r'in (\w+) plugin of type "(\w+)"', message)
    names = set(re.findall(r'- \w+ "(\w+)"', message))
    if not plugin or not names:
        return ""
    tag, kind = plugin.groups()
    removed = []
    for node in root.iter(tag):
        if node.get("type") != kind:
            continue
        for prop in list(node):
            if _snake(prop.get("name") or "") in names:
                node.remove(prop)
                removed.append(prop.get("name"))
    return f"{sorted(set(removed))} of {tag} {kind!r}" if removed else ""
