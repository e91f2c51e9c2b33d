"""Built-in sidecar presets: the layer names and conventions of common renderers.

A preset is a partial sidecar (see ``docs/captured.md``): a default ``file`` pattern, the
``channels`` table (harness channel -> layer, or ``{file, layer, components}``), ``reference``
and ``conventions``. A sidecar naming a preset overrides any of these key by key; a channel set
to ``false`` in the sidecar is dropped. Channels that a preset names but a capture lacks are not
provided (a renderer writes only the passes that were enabled); channels named in the sidecar
itself must be present.

Sources of each preset's conventions:

* ``blender``: Blender 4.x/5.x pass names in a multi-layer EXR of view layer ``ViewLayer``;
  checked against Cycles in Blender 5.0.1 (``bpy``): the ``Vector`` pass holds
  ``previous - current`` in pixels with y up, ``Depth`` is the view-space z with 1e10 for
  background, ``Normal`` and ``Position`` are in world space.
* ``mitsuba``: Mitsuba 3's ``aov`` integrator (``src/integrators/aov.cpp``) as written by
  ``examples/capture/mitsuba_capture.py``: ``depth`` is the ray distance ``si.t`` with 0 for
  background, ``sh_normal`` and ``position`` are in world space; no motion AOV exists.
* ``falcor``: one file per output, named as Falcor's frame capture names them
  (``<base>.<pass>.<output>.<frame>.exr``); ``mvec`` holds ``previous - current`` in UV units
  (fractions of the image, y down), ``linearZ`` the view-space z in its first component.
"""

from __future__ import annotations

#: conventions of the harness's own channels (see ``harness.buffers``)
HARNESS_CONVENTIONS = {
    "motion_vector": "previous_minus_current",
    "motion_units": "pixels",
    "motion_y": "down",
    "normal_space": "world",
    "normal_encoding": "signed",
    "depth": "view_z",
    "color_space": "linear_srgb",
    "origin": "top_left",
}

PRESETS = {
    "harness": {
        "file": "frames/{frame:04d}.exr",
        "channels": {},
        "conventions": {},
    },
    "blender": {
        "file": "{frame:04d}.exr",
        "first_frame": 1,
        "channels": {
            "color": "ViewLayer.Combined",
            "albedo": "ViewLayer.Denoising Albedo",
            "normal": "ViewLayer.Normal",
            "depth": "ViewLayer.Depth",
            "position": "ViewLayer.Position",
            "motion": {"layer": "ViewLayer.Vector", "components": ["X", "Y"]},
            "emission": "ViewLayer.Emission",
            "object_id": "ViewLayer.Object Index",
        },
        "conventions": {"motion_y": "up", "depth_background": 1e10},
    },
    "mitsuba": {
        "file": "frames/{frame:04d}.exr",
        "channels": {
            "color": "color",
            "albedo": "albedo",
            "normal": "normal",
            "depth": "depth",
            "position": "position",
        },
        "reference": {"file": "reference/{frame:04d}.exr", "layer": ""},
        "conventions": {"depth": "ray_distance", "depth_background": 0.0},
    },
    "falcor": {
        "channels": {
            "color": {"file": "Mogwai.PathTracer.color.{frame}.exr"},
            "albedo": {"file": "Mogwai.PathTracer.albedo.{frame}.exr"},
            "normal": {"file": "Mogwai.GBufferRT.normW.{frame}.exr"},
            "position": {"file": "Mogwai.GBufferRT.posW.{frame}.exr"},
            "depth": {"file": "Mogwai.GBufferRT.linearZ.{frame}.exr"},
            "motion": {"file": "Mogwai.GBufferRT.mvec.{frame}.exr"},
            "emission": {"file": "Mogwai.GBufferRT.emissive.{frame}.exr"},
        },
        "reference": {"file": "reference/Mogwai.AccumulatePass.output.{frame}.exr", "layer": ""},
        "conventions": {"motion_units": "uv"},
    },
}
