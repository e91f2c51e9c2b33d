"""``opencv_jbf``: OpenCV's joint bilateral filter guided by the normals (a speed/quality peer).

``cv2.ximgproc.jointBilateralFilter`` with a 9x9 window (d=9), the shading normal (mapped to
[0, 1]) as the guide, and the noisy colour as the source. Needs opencv-contrib (the ``peers``
extra); the plugin is listed as broken where it is not installed.

Robustness: OpenCV builds a lookup table over the guide's value range, and crashes
(segmentation fault) on a NaN or infinite guide value and returns non-finite output for a
guide of 3.4e38. Normals are unit vectors, so the guide is clipped to [0, 1] (components
outside [-1, 1] saturate) and a NaN component becomes 0.5 (a zero component). The colour is
filtered as a scaled copy (divided by its largest magnitude) so that huge values stay finite
in OpenCV's float32 arithmetic; negative colour is filtered as it is (signed values).
Cost of the guide guards: the unguarded version (commit a698656) took 1.00 (0.89-1.03) times
this one's single-thread CPU time per round at 1280x720, with identical output
(``python benchmarks/bench_eaw_svgf.py --threads 1,2 --rounds 5 --baseline a698656``; 2-core AMD
EPYC VM, load average 16-19).
"""

import cv2  # noqa: E402  (import failure marks this plugin broken, as intended)
import numpy as np

from harness import FilterSpec, Param, hookimpl

PARAMS = {
    "diameter": Param(9, min=1, max=63, doc="window diameter in pixels"),
    "sigma_color": Param(0.2, min=0, min_exclusive=True, max=1e30, doc="range sigma on the guide"),
    "sigma_space": Param(3.0, min=0, min_exclusive=True, max=1e30, doc="spatial sigma in pixels"),
}


class JointBilateral:
    """Joint bilateral filter of ``color`` guided by ``normal``.

    Parameters
    ----------
    backend : {"cpu"}
    diameter : int
        Window diameter in pixels.
    sigma_color : float
        Range sigma on the guide (normals in [0, 1]).
    sigma_space : float
        Spatial sigma in pixels.
    """

    def __init__(self, backend="cpu", diameter=9, sigma_color=0.2, sigma_space=3.0):
        if backend != "cpu":
            raise ValueError(f"opencv_jbf: unsupported backend {backend!r}")
        self.diameter, self.sigma_color, self.sigma_space = int(diameter), float(sigma_color), float(sigma_space)

    def reset(self):
        """Stateless."""

    def __call__(self, frame, sampler=None):
        color = frame["color"]
        # OpenCV works in float32: keep huge values finite by filtering a scaled copy
        scale = float(np.max(np.abs(color))) if color.size else 0.0
        scale = scale if np.isfinite(scale) and scale > 0 else 1.0
        src = np.ascontiguousarray(color / np.float32(scale), np.float32)
        guide = np.asarray(frame["normal"], np.float32) * np.float32(0.5) + np.float32(0.5)
        np.clip(guide, 0.0, 1.0, out=guide)  # also turns +-inf into 1 and 0
        np.nan_to_num(guide, copy=False, nan=0.5)
        out = cv2.ximgproc.jointBilateralFilter(guide, src, self.diameter, self.sigma_color, self.sigma_space)
        return np.ascontiguousarray(out.reshape(color.shape) * np.float32(scale), np.float32)


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="opencv_jbf",
            version=f"1.0+opencv-{cv2.__version__}",
            factory=JointBilateral,
            requires={"color", "normal"},
            convex=True,  # a normalised bilateral filter (checked by the stress battery)
            params=PARAMS,
            description="OpenCV ximgproc joint bilateral filter, 9x9, normal guide (peer)",
        )
    ]
