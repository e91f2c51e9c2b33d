"""File references of a Mitsuba scene (meshes, textures, environment maps), resolved in its folder.

A scene file is untrusted input: a ``filename`` is read only where it lies inside the scene's
folder once resolved (``..``, absolute paths and symbolic links leading elsewhere are refused
with an error naming the element and the file), unless the environment variable
:data:`ALLOW_ENV` is ``1``, which allows files anywhere (a scene whose meshes live in a shared
folder).
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

from .xmlscene import get_string

#: set to ``1`` to let scene files name files outside their folder
ALLOW_ENV = "DENOISE_HARNESS_ALLOW_OUTSIDE_FILES"


def scene_file(node: ET.Element, folder: Path) -> Path:
    """The file named by the ``filename`` parameter of ``node``, inside the scene ``folder``.

    Raises
    ------
    ValueError
        No ``filename``, or one that leads outside ``folder`` (without :data:`ALLOW_ENV`).
    """
    what = f"<{node.tag} type={node.get('type')!r}{_id(node)}>"
    name = get_string(node, "filename")
    if not name:
        raise ValueError(f"{what} names no filename")
    path = Path(folder) / name
    if os.environ.get(ALLOW_ENV, "") == "1":
        return path
    root, target = Path(folder).resolve(), path.resolve()
    if target != root and root not in target.parents:
        raise ValueError(f"{what} names {name!r}, which is outside the scene folder {folder} (set {ALLOW_ENV}=1 "
                         "to allow files outside it)")
    return path


def _id(node: ET.Element) -> str:
    return f" id={node.get('id')!r}" if node.get("id") else ""


__all__ = ["ALLOW_ENV", "scene_file"]
