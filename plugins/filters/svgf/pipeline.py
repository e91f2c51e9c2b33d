"""The SVGF frame pipeline and its history, shared by the ``cpu`` and ``cuda`` backends."""

from __future__ import annotations

import time

import numpy as np

from .params import SVGFParams


def _make_ops(backend: str):
    if backend == "cpu":
        from .cpu import CpuOps

        return CpuOps()
    if backend == "cuda":
        from .cuda import CudaOps

        return CudaOps()
    raise ValueError(f"svgf: unsupported backend {backend!r}; choose 'cpu' or 'cuda'")


class SVGF:
    """Spatiotemporal variance-guided filter (Schied et al., HPG 2017).

    Parameters
    ----------
    backend : {"cpu", "cuda"}
    **params
        See :class:`plugins.filters.svgf.params.SVGFParams`; unknown names raise ``TypeError``.

    Attributes
    ----------
    stage_ms : dict
        Milliseconds of each stage of the last call: ``prepare``, ``reprojection``,
        ``variance``, ``atrous_0`` ... ``atrous_{N-1}``, ``remodulate``, ``total``.

    Notes
    -----
    Frames with ``direct`` and ``indirect`` are filtered as two signals (each demodulated by
    the albedo) unless ``separate_lighting=False``, others as one (``color``). With an
    ``emission`` channel the emitted radiance is subtracted from ``color`` (or ``direct``)
    before demodulation and added back, unfiltered, after remodulation. History is
    dropped on :meth:`reset`, when a frame's ``meta.camera_cut`` is set, and when the size or
    the number of signals changes.
    """

    def __init__(self, backend: str = "cpu", **params):
        self.params = SVGFParams.from_kwargs(**params)
        self.backend = backend
        self._ops = _make_ops(backend)
        self._history = None
        self._last_variance = None
        self.stage_ms: dict = {}

    def reset(self) -> None:
        """Forget all history (new sequence or camera cut)."""
        self._history = None

    def _allocate(self, nsig: int, h: int, w: int) -> dict:
        ops = self._ops
        f32, f64 = np.float32, np.float64
        return {
            "sig": ops.empty((nsig, 3, h, w), f32),
            "albedo": ops.empty((3, h, w), f32),
            "valid": ops.empty((h, w), np.uint8),
            "depth": ops.empty((h, w), f32),
            "normal": ops.empty((3, h, w), f32),
            "obj": ops.empty((h, w), np.int32),
            "motion": ops.empty((2, h, w), f32),
            "grad": ops.empty((2, h, w), f32),
            "acc_sig": ops.empty((nsig, 3, h, w), f32),
            "mom": ops.empty((nsig, 2, h, w), f64),
            "hist": ops.empty((h, w), f32),
            "var": ops.empty((nsig, h, w), f64),
            "sig_b": ops.empty((nsig, 3, h, w), f32),
            "var_b": ops.empty((nsig, h, w), f64),
            "var_c": ops.empty((nsig, h, w), f64),
            "out": ops.empty((h, w, 3), f32),
        }

    def __call__(self, frame, sampler=None) -> np.ndarray:
        """Filter one frame of a sequence; returns (H, W, 3) float32."""
        p = self.params
        ops = self._ops
        h, w = frame.height, frame.width
        nsig = 2 if (p.separate_lighting and "direct" in frame and "indirect" in frame) else 1
        if frame.meta.camera_cut:
            self.reset()
        prev = self._history
        if prev is not None and prev["feedback"].shape != (nsig, 3, h, w):
            prev = self._history = None
        cur = self._allocate(nsig, h, w)
        if prev is None:
            prev = {k: cur[k] for k in ("valid", "depth", "normal", "obj")}
            prev.update(feedback=cur["acc_sig"], mom=cur["mom"], hist=cur["hist"])
        times = {}
        ops.synchronize()
        t_start = t = time.perf_counter()

        def lap(name):
            nonlocal t
            ops.synchronize()
            now = time.perf_counter()
            times[name] = (now - t) * 1e3
            t = now

        color = ops.upload(frame["color"])
        first = ops.upload(frame["direct"]) if nsig == 2 else color
        second = ops.upload(frame["indirect"]) if nsig == 2 else color
        has_emission = "emission" in frame
        # without the channel a 1x1 stand-in keeps one compiled signature (it is never read)
        emission = ops.upload(frame["emission"] if has_emission else np.zeros((1, 1, 3), np.float32))
        ops.prepare(first, second, nsig, emission, has_emission, ops.upload(frame["albedo"]),
                    ops.upload(frame["normal"]), ops.upload(frame["depth"]), ops.upload(frame["object_id"]),
                    ops.upload(frame["motion"]), p.albedo_epsilon, cur["sig"], cur["albedo"],
                    cur["valid"], cur["depth"], cur["normal"], cur["obj"], cur["motion"], cur["grad"])
        lap("prepare")
        ops.reproject(cur["sig"], cur["valid"], cur["depth"], cur["normal"], cur["obj"], cur["grad"],
                      cur["motion"], prev["feedback"], prev["mom"], prev["hist"], prev["valid"],
                      prev["depth"], prev["normal"], prev["obj"], self._history is not None,
                      p.depth_tolerance, p.normal_tolerance, p.alpha_color, p.alpha_moments,
                      bool(p.history_average), p.max_history, cur["acc_sig"], cur["mom"], cur["hist"])
        lap("reprojection")
        ops.variance(cur["mom"], cur["hist"], cur["valid"], cur["depth"], cur["normal"], cur["grad"],
                     p.variance_frames, p.sigma_z, p.sigma_n, p.sigma_n_int, p.depth_epsilon,
                     cur["var"])
        lap("variance")
        # ping-pong through free buffers; the feedback buffer is kept for the next frame
        src, feedback = cur["acc_sig"], None
        free = [cur["sig_b"], cur["sig"]]  # the demodulated input is not needed any more
        if p.feedback_iteration == -1:
            feedback = src
        var, var_free = cur["var"], [cur["var_b"], cur["var_c"]]
        for it in range(p.iterations):
            dst, var_dst = free.pop(0), var_free.pop(0)
            # the signals of the feedback and the last iteration are read afterwards
            keep = it == p.feedback_iteration or it == p.iterations - 1
            ops.atrous(it, p.iterations, src, var, cur["valid"], cur["depth"], cur["normal"],
                       cur["grad"], p.sigma_z, p.sigma_n, p.sigma_l, p.depth_epsilon,
                       p.luminance_epsilon, dst, var_dst, keep)
            if it == p.feedback_iteration:
                feedback = dst
            if src is not feedback:
                free.append(src)
            if var is not cur["var"]:
                var_free.append(var)
            src, var = dst, var_dst
            lap(f"atrous_{it}")
        ops.remodulate(src, cur["albedo"], cur["valid"], color, emission, has_emission, cur["out"])
        out = ops.download(cur["out"])
        lap("remodulate")
        times["total"] = (time.perf_counter() - t_start) * 1e3
        self.stage_ms = times
        self._history = {k: cur[k] for k in ("mom", "hist", "valid", "depth", "normal", "obj")}
        self._history["feedback"] = feedback
        self._last_variance = cur["var"]
        return np.ascontiguousarray(out, dtype=np.float32)

    def history_length(self) -> np.ndarray | None:
        """History length (frames) of every pixel after the last call, (H, W) float32."""
        if self._history is None:
            return None
        return np.array(self._ops.download(self._history["hist"]), dtype=np.float32)

    def variance_estimate(self) -> np.ndarray | None:
        """Luminance variance of each demodulated signal estimated in the last call, before
        the à-trous iterations: (S, H, W) float64 (temporal, or spatial where history is short).
        """
        if self._last_variance is None:
            return None
        return np.array(self._ops.download(self._last_variance), dtype=np.float64)
