"""Procedural scenes of the ``synthetic`` renderer."""

from harness import Scene, SceneSpec, hookimpl

VERSION = "1.0"


def _edges() -> Scene:
    return Scene(
        name="synthetic-edges",
        kind="procedural",
        frame_count=1,
        resolution=(128, 96),
        tags={"static", "synthetic", "sky", "shadow"},
        params={"pattern": "edges"},
        source="synthetic",
    )


def _moving() -> Scene:
    return Scene(
        name="synthetic-moving",
        kind="procedural",
        frame_count=16,
        resolution=(128, 96),
        tags={"dynamic", "synthetic", "sky", "shadow", "disocclusion"},
        params={"pattern": "moving", "pan": 0.01, "object_velocity": [0.025, 0.004], "object_start": [0.15, 0.42]},
        source="synthetic",
    )


def _static_sequence() -> Scene:
    return Scene(
        name="synthetic-static",
        kind="procedural",
        frame_count=8,
        resolution=(128, 96),
        tags={"static", "synthetic", "sky", "shadow", "sequence"},
        params={"pattern": "edges"},
        source="synthetic",
    )


@hookimpl
def register_scenes():
    common = dict(version=VERSION, kind="procedural", resolution=(128, 96))
    return [
        SceneSpec(
            name="synthetic-edges",
            factory=_edges,
            tags=_edges().tags,
            frames=1,
            description="regions with normal, depth and albedo edges, a hard shadow and sky",
            **common,
        ),
        SceneSpec(
            name="synthetic-static",
            factory=_static_sequence,
            tags=_static_sequence().tags,
            frames=8,
            description="the edges pattern over 8 frames with a static camera",
            **common,
        ),
        SceneSpec(
            name="synthetic-moving",
            factory=_moving,
            tags=_moving().tags,
            frames=16,
            description="camera pan and a moving object: exact motion vectors and disocclusions",
            **common,
        ),
    ]
