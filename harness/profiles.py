"""Run profiles: named sets of run settings (resolution, frames, seeds, reference quality, timing).

A profile is data: :class:`Profile` rows in :data:`PROFILES`. ``denoise-bench run --profile
NAME`` starts from one (``quick`` by default), any option given on the command line overrides
the profile's value, and the manifest records the profile with the values actually used.
``denoise-bench profiles`` prints the table.

``quick``
    A newcomer's first run: every scene at its own small resolution, sequences cut to their
    first 8 frames, 3 seeds, references of 256 samples per pixel (with their variance, so the
    errors are bias-corrected and the noise floor is on every row), timings at 1280x720 and
    1920x1080 on ``atrium``; the ``real`` tier (scene folders of ``$DENOISE_SCENES`` or
    ``../shared/scenes``, where there are any) at ``real_resolution``. Minutes on 2 cores with an
    empty cache (README).
``paper``
    The scale of the source paper: 1280x720 (both tiers), full sequences, 5 seeds, references
    rendered to a median relative standard error of 1% or 4096 samples per pixel, 5 timed calls
    per frame. Days on 2 cores (docs/paper-comparison.md lists what a slice of it costs).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace

from harness.rows import REAL_RESOLUTIONS


@dataclass(frozen=True)
class Profile:
    """One profile: the defaults of a run.

    Attributes
    ----------
    name, description : str
    resolution : (width, height) or None
        Quality resolution of every scene (None: each scene's own).
    frames : int or None
        Frames per scene, from the first (None: the whole sequence).
    seeds : tuple of int
        Seeds of the noisy input.
    reference_spp : int or None
        Samples per pixel of references, the cap when ``reference_target`` is set (None: the
        renderer's own).
    reference_target : float
        Median relative standard error references stop at (0: exactly ``reference_spp``).
    repeats : int
        Timed calls per frame.
    timing : tuple of (width, height)
        Real resolutions filters are timed at (:data:`harness.rows.REAL_RESOLUTIONS`).
    timing_scene : str
        The scene those timings are taken on (where it is selected and serves the task).
    real_resolution : (width, height) or None
        Resolution of the ``real`` tier's scene folders where ``resolution`` is None (their
        films are usually 1280x720 or more; None: each folder's own).
    """

    name: str
    description: str
    resolution: tuple | None = None
    frames: int | None = None
    seeds: tuple = (0,)
    reference_spp: int | None = None
    reference_target: float = 0.0
    repeats: int = 3
    timing: tuple = REAL_RESOLUTIONS
    timing_scene: str = "atrium"
    real_resolution: tuple | None = None

    def with_overrides(self, **values) -> Profile:
        """This profile with the given fields replaced (values None are ignored)."""
        return replace(self, **{k: v for k, v in values.items() if v is not None})

    def as_dict(self) -> dict:
        """Plain JSON-able values (for the manifest and the listing)."""
        out = asdict(self)
        out["resolution"] = f"{self.resolution[0]}x{self.resolution[1]}" if self.resolution else None
        out["real_resolution"] = (f"{self.real_resolution[0]}x{self.real_resolution[1]}" if self.real_resolution
                                  else None)
        out["seeds"] = list(self.seeds)
        out["timing"] = [f"{w}x{h}" for w, h in self.timing]
        return out


PROFILES: dict[str, Profile] = {
    "quick": Profile(
        name="quick",
        description="first look in minutes on 2 cores: scene resolutions (real tier 128x72), 8 frames, 3 seeds, "
                    "256-spp references",
        frames=8,
        seeds=(0, 1, 2),
        reference_spp=256,
        repeats=3,
        real_resolution=(128, 72),
    ),
    "paper": Profile(
        name="paper",
        description="the source paper's scale: 1280x720 (both tiers), full sequences, 5 seeds, references to 1% or "
                    "4096 spp",
        resolution=(1280, 720),
        seeds=(0, 1, 2, 3, 4),
        reference_spp=4096,
        reference_target=0.01,
        repeats=5,
    ),
}
DEFAULT_PROFILE = "quick"


def get_profile(name: str) -> Profile:
    """The profile called ``name``; ``KeyError`` naming the known ones otherwise."""
    try:
        return PROFILES[name]
    except KeyError:
        raise KeyError(f"no profile {name!r}; profiles: {sorted(PROFILES)}") from None


def profile_table() -> list[dict]:
    """One dict per profile, in :data:`PROFILES` order, with every field."""
    return [p.as_dict() for p in PROFILES.values()]


FIELDS = [f.name for f in fields(Profile)]

__all__ = ["DEFAULT_PROFILE", "FIELDS", "PROFILES", "Profile", "get_profile", "profile_table"]
