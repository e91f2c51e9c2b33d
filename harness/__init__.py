"""denoise-harness: a plugin-based benchmark harness for real-time Monte Carlo denoisers.

This module is the public API. Plugins import only names from here, and the public submodule
``kernels``, imported where it is used (``from harness import kernels``: building blocks of Numba
kernels, fast exp/log, bit casts, the task counter, the small-image serial guard, the backend
handle).
"""

from harness.backends import available_backends, cuda_available, cuda_simulated, load_backend
from harness.buffers import (
    CHANNELS,
    ChannelError,
    Frame,
    FrameMeta,
    NonFiniteError,
    expected_shape,
)
from harness.exr import ExrError, read_channels, read_size, write_capture, write_channels, write_exr
from harness.guides import (
    CAMERA_MOTION,
    camera_motion,
    camera_motion_ready,
    constant_depth,
    one_object,
    pinhole_position,
    static_motion,
    zero_motion,
)
from harness.hookspecs import hookimpl
from harness.images import display_variance, encode_srgb, write_png
from harness.jitter import JITTER_CYCLE, halton_jitter, radical_inverse
from harness.numba_cache import configure_numba_cache
from harness.params import Param
from harness.plugins import PluginConflictError, Registry, load_plugins
from harness.protocols import (
    AdaptiveRenderer,
    ChunkedRenderer,
    Filter,
    KnownNoiseRenderer,
    Metric,
    Renderer,
    StageTimedFilter,
)
from harness.sampling import Sampler, StreamSampler
from harness.scene import (
    CameraPath,
    Environment,
    Material,
    Scene,
    SceneObject,
    Sun,
    TriangleSoup,
    read_texture,
    srgb_to_linear,
)
from harness.specs import TASKS, TIERS, FilterSpec, MetricSpec, RendererSpec, SceneSpec
from harness.stream_renderer import StreamRenderer
from harness.threads import compute_threads
from harness.transforms import rotation, translation

__version__ = "0.1.0"

# before any plugin compiles: a Numba cache keyed by the source (see harness.numba_cache)
configure_numba_cache()

__all__ = [
    "CAMERA_MOTION",
    "camera_motion",
    "camera_motion_ready",
    "constant_depth",
    "one_object",
    "pinhole_position",
    "static_motion",
    "zero_motion",
    "AdaptiveRenderer",
    "CHANNELS",
    "CameraPath",
    "ChannelError",
    "ChunkedRenderer",
    "Environment",
    "ExrError",
    "Filter",
    "FilterSpec",
    "Frame",
    "FrameMeta",
    "JITTER_CYCLE",
    "KnownNoiseRenderer",
    "Material",
    "Metric",
    "MetricSpec",
    "NonFiniteError",
    "Param",
    "PluginConflictError",
    "Registry",
    "Renderer",
    "RendererSpec",
    "Sampler",
    "StreamRenderer",
    "StreamSampler",
    "Scene",
    "SceneObject",
    "SceneSpec",
    "StageTimedFilter",
    "Sun",
    "TASKS",
    "TIERS",
    "TriangleSoup",
    "__version__",
    "available_backends",
    "compute_threads",
    "cuda_available",
    "cuda_simulated",
    "display_variance",
    "encode_srgb",
    "expected_shape",
    "halton_jitter",
    "hookimpl",
    "kernels",
    "load_backend",
    "load_plugins",
    "radical_inverse",
    "read_channels",
    "read_size",
    "read_texture",
    "rotation",
    "srgb_to_linear",
    "translation",
    "write_capture",
    "write_channels",
    "write_exr",
    "write_png",]
