"""Mitsuba 0.6 / 3 XML scene plugin.

Implements the ``open_scene`` hook (``denoise-bench run --scene-dir PATH``) for folders holding a
Mitsuba scene XML (or an ``animation.toml`` naming one), and registers the third-party test scenes
``classroom``, ``living-room`` and ``sponza`` (not in the default suite, tier ``real``), read from
``../shared/scenes/<name>`` relative to the current directory or to the project root. Every scene
is a sequence: its ``animation.toml`` sidecar, or the generated default camera path
(:mod:`.animation`, :mod:`.camera_path`). Approximations are reported as :class:`MitsubaWarning`
warnings, never as failures.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from harness import SceneSpec, hookimpl

from .animation import DEFAULT_FRAMES, AnimationError
from .animation import read as read_animation
from .loader import find_scene_file, load, sidecar_of
from .xmlscene import MitsubaWarning

VERSION = "1.1"
THIRD_PARTY = {
    "classroom": "Japanese Classroom (Mitsuba 0.6 XML, OBJ, textures, sun/sky)",
    "living-room": "The Grey & White Room (Mitsuba 0.6 XML, OBJ, env map, glass, metals)",
    "sponza": "Sponza atrium (Mitsuba 0.6 XML, serialized meshes, textures)",
}
#: default resolution of the registered third-party scenes (their film is 1280x720)
RESOLUTION = (320, 180)


def scene_folder(name: str) -> Path:
    """``../shared/scenes/<name>`` relative to the working directory or the project root.

    Raises
    ------
    FileNotFoundError
        Naming the folders tried.
    """
    tried = []
    for base in (Path.cwd(), _project_root()):
        if base is None:
            continue
        folder = (base / ".." / "shared" / "scenes" / name).resolve()
        tried.append(str(folder))
        if find_scene_file(folder) is not None:
            return folder
    raise FileNotFoundError(f"scene {name!r}: no Mitsuba scene folder found; tried {', '.join(tried)}")


def _project_root() -> Path | None:
    for parent in Path(__file__).resolve().parents:
        if (parent / "pyproject.toml").is_file():
            return parent
    return None


def _factory(name: str):
    def build():
        scene = load(scene_folder(name), name=name)
        return dataclasses.replace(scene, resolution=RESOLUTION)

    build.__name__ = f"build_{name.replace('-', '_')}"
    return build


def declared_frames(name: str) -> int:
    """Frames of a registered scene: its sidecar's where the folder has one, else the default path's."""
    try:
        return read_animation(sidecar_of(scene_folder(name))).frames
    except (FileNotFoundError, AnimationError):
        return DEFAULT_FRAMES


@hookimpl
def register_scenes():
    specs = []
    for name, description in THIRD_PARTY.items():
        frames = declared_frames(name)
        specs.append(SceneSpec(name=name, version=VERSION, factory=_factory(name), frames=frames,
                               tags={"dynamic" if frames > 1 else "static", "mitsuba"}, resolution=RESOLUTION,
                               kind="mesh", suite=False, description=description, tier="real"))
    return specs


@hookimpl
def open_scene(path):
    if find_scene_file(Path(path)) is None:
        return None
    return load(Path(path))


__all__ = ["MitsubaWarning", "load", "scene_folder"]
