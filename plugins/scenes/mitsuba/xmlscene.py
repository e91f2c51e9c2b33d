"""Reading Mitsuba 0.6 / 3 scene XML: defaults, typed properties and transforms.

Property names are matched case- and underscore-insensitively (``toWorld`` = ``to_world``), so
the same code reads Mitsuba 0.6 (camelCase) and Mitsuba 3 (snake_case) files.
"""

from __future__ import annotations

import re
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from harness import rotation


class MitsubaWarning(UserWarning):
    """An element of a Mitsuba scene was approximated or skipped."""


def warn(message: str) -> None:
    """Emit a :class:`MitsubaWarning`."""
    warnings.warn(message, MitsubaWarning, stacklevel=3)


def key(name: str) -> str:
    """The normalised property name: lower case, underscores removed."""
    return name.replace("_", "").lower()


def parse(path: Path) -> ET.Element:
    """Parse a scene file and substitute ``$name`` references with ``<default>`` values."""
    root = ET.parse(path).getroot()
    defaults = {d.get("name"): d.get("value") for d in root.findall("default")}
    pattern = re.compile(r"\$(\w+)")
    for element in root.iter():
        for attr, value in element.attrib.items():
            if "$" in value:
                element.set(attr, pattern.sub(lambda m: defaults.get(m.group(1), m.group(0)), value))
    return root


def version(root: ET.Element) -> tuple[int, ...]:
    """The scene's ``version`` attribute as a tuple (0.6.0 when missing)."""
    text = root.get("version", "0.6.0")
    return tuple(int(p) for p in re.findall(r"\d+", text)) or (0, 6, 0)


def find(element: ET.Element, name: str) -> ET.Element | None:
    """The child property element called ``name`` (any tag), or None."""
    want = key(name)
    for child in element:
        if child.get("name") is not None and key(child.get("name")) == want:
            return child
    return None


def _floats(text: str) -> list[float]:
    return [float(v) for v in re.split(r"[,\s]+", text.strip()) if v]


def get_float(element: ET.Element, name: str, default: float | None = None) -> float | None:
    node = find(element, name)
    if node is None or node.get("value") is None:
        return default
    return float(node.get("value"))


def get_int(element: ET.Element, name: str, default: int | None = None) -> int | None:
    node = find(element, name)
    return default if node is None else int(node.get("value"))


def get_bool(element: ET.Element, name: str, default: bool = False) -> bool:
    node = find(element, name)
    return default if node is None else node.get("value", "false").strip().lower() == "true"


def get_string(element: ET.Element, name: str, default: str | None = None) -> str | None:
    node = find(element, name)
    return default if node is None else node.get("value")


# Mitsuba 3's RGB variants read a constant <spectrum> of an emitter as an equal-energy illuminant,
# whose linear sRGB (white point D65) is this colour times the value
EQUAL_ENERGY_RGB = (1.2047939, 0.9482910, 0.9089161)


def color_value(node: ET.Element, illuminant: bool = False) -> tuple[float, float, float] | None:
    """An ``rgb``/``srgb``/``spectrum``/``float`` node as linear RGB, or None for other tags.

    ``srgb`` is linearised; a ``spectrum`` with wavelength:value pairs is averaged (warned). With
    ``illuminant`` (an emitter's radiance), a constant ``spectrum`` is an equal-energy spectrum
    in sRGB, as Mitsuba 3 renders it: ``value * EQUAL_ENERGY_RGB``.
    """
    if illuminant and node.tag == "spectrum":
        plain = color_value(node)
        if plain is not None and plain[0] == plain[1] == plain[2]:
            return tuple(plain[0] * c for c in EQUAL_ENERGY_RGB)
        return plain
    if node.tag == "float":
        v = float(node.get("value"))
        return (v, v, v)
    if node.tag in ("rgb", "srgb", "color"):
        text = node.get("value", "")
        if text.startswith("#"):
            values = [int(text[k:k + 2], 16) / 255.0 for k in (1, 3, 5)]
            values = [_srgb_to_linear(v) for v in values]
        else:
            values = _floats(text)
            if node.tag == "srgb":
                values = [_srgb_to_linear(v) for v in values]
        values = (values * 3)[:3] if len(values) == 1 else values[:3]
        return tuple(values)
    if node.tag == "spectrum":
        text = node.get("value", "")
        if ":" in text:
            pairs = [p.split(":") for p in re.split(r"[,\s]+", text.strip()) if p]
            mean = float(np.mean([float(v) for _, v in pairs]))
            warn(f"spectrum {text[:40]!r} approximated by its mean value {mean:.4g}")
            return (mean, mean, mean)
        values = _floats(text)
        if len(values) == 1:
            return (values[0],) * 3
        return tuple(values[:3])
    if node.tag == "blackbody":
        warn("blackbody spectrum approximated by white of its 'scale'")
        v = float(node.get("scale", "1"))
        return (v, v, v)
    return None


def _srgb_to_linear(v: float) -> float:
    return v / 12.92 if v <= 0.04045 else ((v + 0.055) / 1.055) ** 2.4


def get_color(element: ET.Element, name: str, default=None, illuminant: bool = False):
    node = find(element, name)
    if node is None:
        return default
    value = color_value(node, illuminant)
    return default if value is None else value


def vector(node: ET.Element, default=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The x, y, z attributes (or ``value``) of a ``point``/``vector``/``translate`` node."""
    if node.get("value") is not None:
        values = _floats(node.get("value"))
        if len(values) == 1:
            values = values * 3
        return np.array(values[:3], float)
    return np.array([float(node.get(a, d)) for a, d in zip("xyz", default)], float)


def transform(node: ET.Element | None) -> np.ndarray:
    """The 4x4 matrix of a ``<transform>`` element; later children apply after earlier ones."""
    m = np.eye(4)
    if node is None:
        return m
    for step in node:
        if step.tag == "matrix":
            t = np.array(_floats(step.get("value")), float).reshape(4, 4)
        elif step.tag == "translate":
            t = np.eye(4)
            t[:3, 3] = vector(step)
        elif step.tag == "scale":
            t = np.eye(4)
            if step.get("value") is not None:
                t[:3, :3] *= float(step.get("value"))
            else:
                t[:3, :3] = np.diag(vector(step, (1.0, 1.0, 1.0)))
        elif step.tag == "rotate":
            t = rotation(vector(step), float(step.get("angle", "0")))
        elif step.tag == "lookat":
            t = lookat(step)
        else:
            warn(f"unknown transform step <{step.tag}> skipped")
            continue
        m = t @ m
    return m


def lookat(node: ET.Element) -> np.ndarray:
    """Mitsuba's look-at camera-to-world matrix: camera looks along +z, y up, x to the left."""
    origin = np.array(_floats(node.get("origin")), float)
    target = np.array(_floats(node.get("target")), float)
    up = np.array(_floats(node.get("up", "0 1 0")), float)
    direction = target - origin
    direction /= np.linalg.norm(direction)
    left = np.cross(up, direction)
    left /= max(np.linalg.norm(left), 1e-12)
    new_up = np.cross(direction, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, direction, origin
    return m
