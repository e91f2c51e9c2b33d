"""Where a built-in scene's ``SPEC`` constants become the fields of its :class:`harness.Scene`."""

from __future__ import annotations

from harness import Scene

#: the ``source`` of every built-in scene
SOURCE = "plugins.scenes.builtin"


def suite_scene(spec: dict, **fields) -> Scene:
    """A scene with the name, frame count, resolution and tags of a builder's ``SPEC``.

    Parameters
    ----------
    spec : dict
        The builder module's ``SPEC`` (``name``, ``frames``, ``resolution``, ``tags``), the same
        constants its registered :class:`harness.SceneSpec` declares.
    **fields
        The other :class:`harness.Scene` fields (objects, materials, lights, camera ...).

    Returns
    -------
    harness.Scene
    """
    return Scene(name=spec["name"], frame_count=spec["frames"], resolution=spec["resolution"], tags=spec["tags"],
                 source=SOURCE, **fields)
