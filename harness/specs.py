"""Plugin specs: what each kind of plugin declares to the harness.

Every spec is a small frozen dataclass with a unique ``name``, a ``version`` (part of every
cache key and of the run manifest) and a ``factory`` that builds the working object.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from harness.buffers import CHANNELS
from harness.guides import CAMERA_MOTION, camera_motion_ready
from harness.params import Param, param_table

BACKENDS = ("cpu", "cuda")
#: optional inputs a metric may declare in ``MetricSpec.accepts``
METRIC_INPUTS = ("reference_variance", "mask")
#: the benchmark tasks: ``denoise`` (1-spp path-traced input, converged path-traced reference) and
#: ``antialias`` (one jittered shading sample per pixel, supersampled reference)
TASKS = ("denoise", "antialias")
#: scene tiers: content built by this project, and third-party content (DESIGN.md, "Tiers and guides")
TIERS = ("procedural", "real")


def _check_tasks(owner: str, tasks) -> frozenset[str]:
    tasks = frozenset([tasks] if isinstance(tasks, str) else tasks)
    unknown = sorted(tasks - set(TASKS))
    if unknown or not tasks:
        raise ValueError(f"{owner}: tasks must be a non-empty subset of {TASKS}, got {sorted(tasks)}")
    return tasks


def _frozen_mapping(value: Mapping[str, Any] | None) -> Mapping[str, Any]:
    return MappingProxyType(dict(value or {}))


def _check_channels(owner: str, names) -> frozenset[str]:
    names = frozenset(names)
    unknown = sorted(names - set(CHANNELS))
    if unknown:
        raise ValueError(f"{owner}: unknown channel(s) {unknown}; known channels are {sorted(CHANNELS)}")
    return names


@dataclass(frozen=True)
class FilterSpec:
    """Declaration of a reconstruction filter.

    Parameters
    ----------
    name : str
        Unique plugin name, used on the command line and in result tables.
    version : str
        Version of the implementation; changes invalidate stored results.
    factory : callable
        ``factory(backend="cpu", **params)`` returns a filter object with ``reset()`` and
        ``__call__(frame, sampler=None) -> ndarray (H, W, 3) float32``.
    requires : iterable of str
        Frame channels the filter reads (``color`` is always implied). A job whose renderer
        cannot provide one of them is skipped with that reason.
    optional : iterable of str
        Channels the filter uses when the renderer provides them (e.g. ``direct``/``indirect``).
        The filter sees only ``requires`` and the ``optional`` channels that were rendered.
    full_guides : iterable of str, optional
        The guide channels of the full algorithm (the paper's), among ``requires`` and
        ``optional``. A job whose frames lack some of them runs the filter's degraded mode: its
        rows' ``guides`` column names the guides it had and ``without`` the others, and the
        leaderboard marks its entry. None: ``requires`` (never degraded).
    motion_from_camera : bool
        True if, on frames without ``motion``, the filter derives the motion of static geometry
        from the camera (:func:`harness.camera_motion`) where the frames allow it
        (:func:`harness.camera_motion_ready`); the ``guides`` column then lists
        ``motion(camera)`` among the guides it had, and ``motion`` still among those it lacked.
    temporal : bool
        True if the filter keeps history between frames of a sequence.
    backends : tuple of str
        Subset of ``("cpu", "cuda")``.
    params : mapping
        Parameter names and their defaults, or :class:`harness.Param` declarations (default,
        type, range, choices). A plain default declares its type (``int``, ``float``, ``bool``,
        ``str``; ``None`` accepts anything). Every ``--param`` and preset is checked against
        these before any work; ``spec.params`` always holds the plain defaults and
        ``spec.param_specs`` the declarations.
    adaptive : bool
        True if the filter asks the renderer for more samples through a ``Sampler``.
    presets : mapping
        Named parameter sets (``{"paper": {...}, "falcor": {...}}``).
    description : str
        One line shown by ``denoise-bench plugins``.
    xfail_checks : mapping of str to str
        Conformance checks (``harness.testing.checks`` function names) this filter knowingly
        fails, each with the reason; they run as strict expected failures.
    trainer : callable, optional
        For learned filters: ``trainer(seed=0, output=None, quick=False, **options) -> pathlib.Path``
        trains the model and writes its weights (``denoise-bench train NAME [-o KEY=VALUE ...]``);
        ``options`` are the trainer's own (a trainer without them need not accept any; an unknown
        one is a ``ValueError``).
    stage_timing : bool
        True if the filter object sets ``stage_ms`` (dict of stage name to milliseconds of the
        last call; see :class:`harness.protocols.StageTimedFilter`); the harness stores it with
        each row and ``denoise-bench bench`` prints it as a per-stage breakdown.
    tasks : iterable of str
        Benchmark tasks the filter serves (:data:`TASKS`); ``("denoise",)`` by default.
    convex : bool
        True if every output value is a convex combination of input radiance (non-negative
        weights summing to one): each output channel then lies within [min, max] of the input's
        colour since the last ``reset()`` or camera cut, and ``denoise-bench stress`` checks it.
    range_gain : float
        The local range bound the stress battery checks on every filter (``local_range``):
        each output pixel's magnitude is at most ``range_gain`` times the largest input
        radiance magnitude within ``range_radius`` pixels of it (since the last ``reset()`` or
        camera cut). Default :data:`RANGE_GAIN` (4).
    range_radius : int, optional
        Half-width of that window in pixels (a square); None (the default) takes the whole
        frame, the right window for filters whose support is wide (à-trous, large windows).
    stress_exempt : mapping of str to str
        Stress cases (:mod:`harness.stress.cases` names, or ``fnmatch`` patterns such as
        ``"guide-normal-*"``) that do not apply to this filter, each with the measured reason.
        They still run; a failure is reported as ``exempt`` and, in pytest, as a strict
        expected failure.
    """

    name: str
    version: str
    factory: Callable[..., Any]
    requires: frozenset = frozenset({"color"})
    optional: frozenset = frozenset()
    full_guides: frozenset | None = None
    motion_from_camera: bool = False
    temporal: bool = False
    backends: tuple = ("cpu",)
    params: Mapping[str, Any] = field(default_factory=dict)
    adaptive: bool = False
    presets: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    description: str = ""
    xfail_checks: Mapping[str, str] = field(default_factory=dict)
    trainer: Callable[..., Any] | None = None
    stage_timing: bool = False
    tasks: frozenset = frozenset({"denoise"})
    convex: bool = False
    range_gain: float = 4.0
    range_radius: int | None = None
    stress_exempt: Mapping[str, str] = field(default_factory=dict)
    param_specs: Mapping[str, Param] = field(default_factory=dict, init=False, compare=False)

    def __post_init__(self):
        owner = f"filter {self.name!r}"
        object.__setattr__(self, "requires", _check_channels(owner, set(self.requires) | {"color"}))
        object.__setattr__(self, "optional", _check_channels(f"filter {self.name!r}", self.optional) - self.requires)
        full = self.requires - {"color"} if self.full_guides is None else frozenset(self.full_guides)
        if full - self.requires - self.optional:
            raise ValueError(f"{owner}: full_guides {sorted(full - self.requires - self.optional)} are neither "
                             "required nor optional")
        object.__setattr__(self, "full_guides", full)
        bad = [b for b in self.backends if b not in BACKENDS]
        if bad or not self.backends:
            raise ValueError(
                f"filter {self.name!r}: backends must be a non-empty subset of {BACKENDS}, got {self.backends}"
            )
        object.__setattr__(self, "backends", tuple(self.backends))
        specs = param_table(owner, self.params)
        object.__setattr__(self, "param_specs", _frozen_mapping(specs))
        object.__setattr__(self, "params", _frozen_mapping({k: p.default for k, p in specs.items()}))
        object.__setattr__(self, "xfail_checks", _frozen_mapping(self.xfail_checks))
        object.__setattr__(self, "stress_exempt", _frozen_mapping(self.stress_exempt))
        empty = sorted(k for k, v in self.stress_exempt.items() if not str(v).strip())
        if empty:
            raise ValueError(f"{owner}: stress_exempt needs a measured reason for each case, none given for {empty}")
        object.__setattr__(self, "presets", _frozen_mapping({k: _frozen_mapping(v) for k, v in self.presets.items()}))
        object.__setattr__(self, "tasks", _check_tasks(owner, self.tasks))
        if not (isinstance(self.range_gain, (int, float)) and 1.0 <= self.range_gain < float("inf")):
            raise ValueError(f"{owner}: range_gain must be a finite number >= 1, got {self.range_gain!r}")
        if self.range_radius is not None and (isinstance(self.range_radius, bool) or not isinstance(
                self.range_radius, int) or self.range_radius < 0):
            raise ValueError(f"{owner}: range_radius must be None or an integer >= 0, got {self.range_radius!r}")
        for preset, values in self.presets.items():
            self.check_params(values, context=f"preset {preset!r}")

    def check_params(self, values: Mapping[str, Any], context: str = "") -> dict:
        """Validate parameter values against :attr:`param_specs`.

        Parameters
        ----------
        values : mapping
            Parameter names and values (a subset of the declared parameters).
        context : str
            Named in the message (e.g. ``"preset 'fast'"``).

        Returns
        -------
        dict
            The values, with ints widened to float where the parameter is a float.

        Raises
        ------
        ValueError
            One line naming the filter, the parameter, what it accepts and what it got.
        """
        where = f"filter {self.name!r}" + (f" {context}" if context else "")
        unknown = sorted(set(values) - set(self.param_specs))
        if unknown:
            raise ValueError(f"{where} has no parameter(s) {unknown}; parameters: {sorted(self.param_specs)}")
        return {k: self.param_specs[k].check(v, owner=f"{where}: parameter {k!r}") for k, v in values.items()}

    def guides_used(self, channels, metas=()) -> str:
        """The ``guides`` column of a job whose frames hold ``channels``: the guide channels the
        filter reads (comma-separated), then ``; without X,Y`` where some of :attr:`full_guides`
        are missing (the degraded mode). With :attr:`motion_from_camera`, frames without
        ``motion`` whose metadata ``metas`` (one :class:`harness.FrameMeta` per frame) allow it
        add ``motion(camera)`` to the guides it had."""
        seen = (self.requires | self.optional) & set(channels)
        used = sorted(seen - {"color"})
        if self.motion_from_camera and "motion" not in seen and camera_motion_ready(seen, metas):
            used = sorted([*used, CAMERA_MOTION])
        missing = sorted(self.full_guides - set(channels))
        return ",".join(used) + (f"; without {','.join(missing)}" if missing else "")

    def declarations(self) -> dict:
        """What the spec declares, as plain JSON-able data."""
        return {
            "requires": sorted(self.requires),
            "optional": sorted(self.optional),
            "full_guides": sorted(self.full_guides),
            "motion_from_camera": self.motion_from_camera,
            "temporal": self.temporal,
            "backends": list(self.backends),
            "params": dict(self.params),
            "adaptive": self.adaptive,
            "presets": sorted(self.presets),
            "trainable": self.trainer is not None,
            "stage_timing": self.stage_timing,
            "tasks": sorted(self.tasks),
            "convex": self.convex,
            "range_gain": self.range_gain,
            "range_radius": self.range_radius,
            "stress_exempt": dict(self.stress_exempt),
        }


@dataclass(frozen=True)
class RendererSpec:
    """Declaration of a renderer.

    Parameters
    ----------
    name, version, factory
        As for :class:`FilterSpec`; ``factory(**settings)`` returns an object with
        ``render(scene, frame_index, *, spp, seed, channels, resolution) -> Frame``,
        ``reference(scene, frame_index, *, spp, seed, resolution) -> ndarray`` (when
        ``references``), ``accumulate(scene, frame_index, *, first_sample, count, seed,
        resolution) -> ndarray`` (when ``chunked``), ``sampler(scene, frame_index, *, spp,
        seed, channels, resolution) -> Sampler`` (when ``adaptive``),
        ``reference_variance(scene, frame_index) -> ndarray or None`` (when
        ``reference_noise``), and ``settings() -> dict`` (part of cache keys). See
        :mod:`harness.protocols`.
    provides : iterable of str
        Channels the renderer can produce.
    references : bool
        Whether it renders converged references.
    adaptive : bool
        Whether it serves adaptive sampling through :class:`harness.Sampler`.
    scene_kinds : iterable of str
        Kinds of :class:`harness.Scene` it understands (``"procedural"``, ``"mesh"``).
    reference_spp : int
        Default samples per pixel of its references.
    chunked : bool
        True if the renderer has ``accumulate`` (the float64 sum of a range of samples):
        references are then rendered in resumable, distributable chunks.
    reference_noise : bool
        True if the renderer has ``reference_variance``: its references come with their
        per-pixel variance of the mean (None where unknown), as stored references do
        (``captured``); chunked renderers' variance is estimated by the harness instead.
    tasks : iterable of str
        Benchmark tasks whose input and reference it makes (:data:`TASKS`).
    deterministic : bool
        True if it returns the same frames for every seed (captured frames): the planner then
        runs one seed, and the leaderboard's tests resample over frames and scenes only.
    scene_tiers : iterable of str
        Tiers (:data:`TIERS`) of the scenes of its kinds that it renders (default: every tier;
        ``mitsuba`` renders the ``real`` tier's Mitsuba XML scenes only). Elsewhere the planner
        skips it with the reason.
    sample_block : int
        Samples of a pixel that a chunked renderer draws together (stratified, so correlated
        with each other): a reference's batches are whole blocks, so that the batch-means
        variance sees independent batches (1: every sample independent).
    """

    name: str
    version: str
    factory: Callable[..., Any]
    provides: frozenset = frozenset()
    references: bool = True
    adaptive: bool = False
    scene_kinds: frozenset = frozenset({"mesh"})
    reference_spp: int = 4096
    description: str = ""
    chunked: bool = False
    tasks: frozenset = frozenset({"denoise"})
    reference_noise: bool = False
    deterministic: bool = False
    scene_tiers: frozenset = frozenset(TIERS)
    sample_block: int = 1

    def __post_init__(self):
        object.__setattr__(self, "provides", _check_channels(f"renderer {self.name!r}", self.provides))
        if isinstance(self.sample_block, bool) or not isinstance(self.sample_block, int) or self.sample_block < 1:
            raise ValueError(f"renderer {self.name!r}: sample_block must be an integer >= 1, got {self.sample_block!r}")
        object.__setattr__(self, "scene_kinds", frozenset(self.scene_kinds))
        object.__setattr__(self, "scene_tiers", frozenset(self.scene_tiers))
        if not self.scene_tiers <= frozenset(TIERS):
            raise ValueError(f"renderer {self.name!r}: scene_tiers must be among {TIERS}, "
                             f"got {sorted(self.scene_tiers)}")
        object.__setattr__(self, "tasks", _check_tasks(f"renderer {self.name!r}", self.tasks))

    def declarations(self) -> dict:
        return {
            "provides": sorted(self.provides),
            "references": self.references,
            "adaptive": self.adaptive,
            "scene_kinds": sorted(self.scene_kinds),
            "reference_spp": self.reference_spp,
            "chunked": self.chunked,
            "reference_noise": self.reference_noise,
            "deterministic": self.deterministic,
            "scene_tiers": sorted(self.scene_tiers),
            "sample_block": self.sample_block,
            "tasks": sorted(self.tasks),
        }


@dataclass(frozen=True)
class MetricSpec:
    """Declaration of an error metric.

    Parameters
    ----------
    name, version, factory
        ``factory()`` returns a callable. A ``"frame"`` metric is called as
        ``metric(output, reference) -> float`` on (H, W, 3) float32 linear images; a
        ``"sequence"`` metric as ``metric(outputs, references) -> float`` on lists of them.
    higher_is_better : bool
        Direction of the score (used by the leaderboard).
    kind : {"frame", "sequence"}
    min_frames : int
        Fewest frames the metric can score (a sequence metric needs at least 2).
    accepts : iterable of str
        Optional keyword arguments the metric takes (:data:`METRIC_INPUTS`); the harness passes
        exactly these: ``reference_variance`` (the reference's per-pixel variance of the mean,
        (H, W, 3), or None where unknown) and ``mask`` ((H, W) bool, True where a pixel is
        scored, or None for every pixel). A sequence metric gets lists of them, one per frame.
    noise_floor : str
        The results column holding the reference's noise floor in this metric's units
        (``reference_noise``, ``reference_noise_display``), for metrics that have one: the
        leaderboard marks a difference smaller than it as not resolved by the references.
    per_frame : bool
        A ``"sequence"`` metric with ``min_frames <= 2`` that is also meaningful on each pair
        of consecutive frames: the harness scores it on frames (t - 1, t) for every t >= 1 and
        stores that value on frame t's row in the column :func:`harness.rows.per_frame_column` (e.g.
        ``temporal_error_per_frame``), beside the sequence value on the last frame's row (a
        time series, e.g. flicker over the frames).
    """

    name: str
    version: str
    factory: Callable[..., Any]
    higher_is_better: bool = False
    kind: str = "frame"
    min_frames: int = 1
    description: str = ""
    accepts: frozenset = frozenset()
    noise_floor: str = ""
    per_frame: bool = False

    def __post_init__(self):
        if self.kind not in ("frame", "sequence"):
            raise ValueError(f"metric {self.name!r}: kind must be 'frame' or 'sequence', got {self.kind!r}")
        accepts = frozenset([self.accepts] if isinstance(self.accepts, str) else self.accepts)
        unknown = sorted(accepts - set(METRIC_INPUTS))
        if unknown:
            raise ValueError(f"metric {self.name!r}: accepts unknown input(s) {unknown}; known: {list(METRIC_INPUTS)}")
        object.__setattr__(self, "accepts", accepts)
        if self.per_frame and (self.kind != "sequence" or self.min_frames > 2):
            raise ValueError(f"metric {self.name!r}: per_frame needs kind 'sequence' and min_frames <= 2")

    def declarations(self) -> dict:
        return {"higher_is_better": self.higher_is_better, "kind": self.kind, "min_frames": self.min_frames,
                "accepts": sorted(self.accepts), "noise_floor": self.noise_floor, "per_frame": self.per_frame}


@dataclass(frozen=True)
class SceneSpec:
    """Declaration of a scene.

    Parameters
    ----------
    name, version, factory
        ``factory()`` returns a :class:`harness.Scene`.
    tags : iterable of str
        E.g. ``static``/``dynamic``, ``glossy``, ``foliage``, ``emissive``, ``sky``.
    frames : int
        Number of frames of the sequence.
    resolution : (int, int)
        Default (width, height).
    kind : str
        ``"procedural"`` (synthetic patterns) or ``"mesh"`` (geometry for raster/path tracing).
    suite : bool
        Whether the scene belongs to the built-in default suite of ``denoise-bench run``.
    tasks : iterable of str
        Benchmark tasks the scene is meant for (:data:`TASKS`).
    channels : iterable of str, optional
        The channels the scene can give where it limits its renderer (captured frames); None
        means whatever the renderer provides. A filter needing another is skipped with a reason.
    tier : {"procedural", "real"}
        ``procedural``: content built by this project (the built-in scenes); ``real``: third-party
        content (Mitsuba scene folders, captures a user names). Leaderboards rank each tier on its
        own (:data:`TIERS`).
    """

    name: str
    version: str
    factory: Callable[..., Any]
    tags: frozenset = frozenset()
    frames: int = 1
    resolution: tuple = (256, 256)
    kind: str = "mesh"
    suite: bool = True
    description: str = ""
    tasks: frozenset = frozenset({"denoise"})
    channels: frozenset | None = None
    tier: str = "procedural"

    def __post_init__(self):
        if self.tier not in TIERS:
            raise ValueError(f"scene {self.name!r}: tier must be one of {TIERS}, got {self.tier!r}")
        object.__setattr__(self, "tags", frozenset(self.tags))
        if self.channels is not None:
            object.__setattr__(self, "channels", _check_channels(f"scene {self.name!r}", self.channels))
        object.__setattr__(self, "tasks", _check_tasks(f"scene {self.name!r}", self.tasks))
        object.__setattr__(self, "resolution", tuple(int(v) for v in self.resolution))
        if self.frames < 1:
            raise ValueError(f"scene {self.name!r}: frames must be >= 1, got {self.frames}")

    def declarations(self) -> dict:
        return {
            "tags": sorted(self.tags),
            "frames": self.frames,
            "resolution": list(self.resolution),
            "kind": self.kind,
            "suite": self.suite,
            "tasks": sorted(self.tasks),
            "tier": self.tier,
        }
