"""Timings at real resolutions: the frames filters are timed on, whatever size quality is scored at.

Quality is scored at each scene's resolution (small by default, so that references are
affordable), but a filter's cost depends on its pixel count and footprint, so the leaderboard's
time columns come from frames of real sizes (:data:`harness.rows.REAL_RESOLUTIONS`: 1280x720
and 1920x1080). They need no reference: the groups the planner picks per task
(:func:`harness.plan.timing_groups`: the profile's timing scene and the first seed, one group
per spp of the run) render their first two frames again at each real resolution, with the same
channels, samples per pixel and seed, through the render cache and the non-finite policy; each
job of those groups then times its filter on them (:func:`harness.timer.time_real_resolutions`):
one call on the first frame (compilation, history), ``repeats`` timed calls on the second. The
results are the ``ms_1280x720`` and ``ms_1920x1080`` columns of that job's rows, so every
configuration has a time at each spp (:func:`harness.pareto.configuration_points` uses the
time at the configuration's own spp).
"""

from __future__ import annotations

from harness.nonfinite import apply_nonfinite_policy
from harness.plan import Group
from harness.renders import RenderStore

#: frames rendered at each real resolution: a warm-up (and history) frame and the timed one
TIMING_FRAMES = 2


def timing_frames(store: RenderStore, group: Group, nonfinite: str = "raise") -> dict:
    """The frames a timing group's jobs are timed on: (width, height) -> list of Frame.

    Parameters
    ----------
    store : RenderStore
        The run's store (its cache, scenes and renderers are shared).
    group : Group
        A group whose ``timing`` lists real resolutions (empty: nothing is rendered).
    nonfinite : {"raise", "repair"}
        The run's policy for non-finite renderer output.
    """
    out = {}
    count = min(TIMING_FRAMES, group.frames)
    for width, height in group.timing:
        sized = store.at_resolution((width, height))
        frames = []
        for t in range(count):
            frame = sized.frame(group.scene, group.renderer, t, spp=group.spp, seed=group.seed,
                                channels=group.channels)
            frames.append(apply_nonfinite_policy(frame, nonfinite, owner=f"renderer {group.renderer!r}")[0])
        out[(width, height)] = frames
    return out


__all__ = ["TIMING_FRAMES", "timing_frames"]
