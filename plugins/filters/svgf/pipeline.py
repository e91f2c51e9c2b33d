"""The SVGF frame pipeline and its history, shared by the ``cpu`` and ``cuda`` backends."""

from __future__ import annotations

import time

import numpy as np

from harness import camera_motion, constant_depth, kernels, load_backend, one_object, zero_motion

from .params import SVGFParams

#: the backends, each a module of this package with an ``Ops`` class (array allocation, copies
#: and the stage launches: ``prepare``, ``reproject``, ``variance``, ``atrous``, ``remodulate``)
BACKENDS = ("cpu", "cuda")


def _frame_set(ops, nsig: int, h: int, w: int) -> dict:
    """The arrays of one frame that become the next frame's history."""
    return {
        "valid": ops.empty((h, w), np.uint8),
        "depth": ops.empty((h, w), np.float32),
        "normal": ops.empty((3, h, w), np.float32),
        "obj": ops.empty((h, w), np.int32),
        "mom": ops.empty((nsig, 2, h, w), np.float64),
        "hist": ops.empty((h, w), np.float32),
        "acc_sig": ops.empty((nsig, 3, h, w), np.float32),
        "feedback": ops.empty((nsig, 3, h, w), np.float32),
    }


def _scratch(ops, nsig: int, h: int, w: int) -> dict:
    """Arrays used within one frame only."""
    return {
        "sig": ops.empty((nsig, 3, h, w), np.float32),
        "albedo": ops.empty((3, h, w), np.float32),
        "motion": ops.empty((2, h, w), np.float32),
        "grad": ops.empty((2, h, w), np.float32),
        "var": ops.empty((nsig, h, w), np.float64),
        "sig_a": ops.empty((nsig, 3, h, w), np.float32),
        "sig_b": ops.empty((nsig, 3, h, w), np.float32),
        "var_a": ops.empty((nsig, h, w), np.float64),
        "var_b": ops.empty((nsig, h, w), np.float64),
    }


def _with_stand_ins(frame):
    """``frame`` with neutral stand-ins for missing ``depth`` (1: the depth stop passes),
    ``object_id`` (0: one object) and ``motion`` (0; the history is dropped then)."""
    shape = frame.shape
    missing = {"depth": constant_depth, "object_id": one_object, "motion": zero_motion}
    added = {name: make(shape) for name, make in missing.items() if name not in frame}
    return frame.replace(**added) if added else frame


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
    ``color`` is the authority. Frames with ``indirect`` are filtered as two signals (each
    demodulated by the albedo): ``indirect`` and ``color - indirect`` (the direct light when the
    split is consistent), unless ``separate_lighting=False``; others as one (``color``). With an
    ``emission`` channel the emitted radiance is subtracted from ``color`` before demodulation
    and added back, unfiltered, after remodulation. History is dropped on :meth:`reset`, when a
    frame's ``meta.camera_cut`` is set, and when the size or the number of signals changes.
    All arrays are kept between frames of one size (two sets for the history, used in turn);
    each call returns a new output array.
    """

    def __init__(self, backend: str = "cpu", **params):
        self.params = SVGFParams.from_kwargs(**params)
        self.backend = backend
        self._ops = load_backend(__package__, backend, BACKENDS, owner="svgf").Ops()
        self._key = None
        self._sets = None  # two frame sets: the current frame's and the history
        self._scratch = None
        self._previous = None  # index of the set holding the history, None without history
        self._jitter = (0.0, 0.0)  # the jitter of the history's frame (in the next prev_view_proj)
        self._last_variance = None
        self.stage_ms: dict = {}

    def reset(self) -> None:
        """Forget all history (new sequence or camera cut)."""
        self._previous = None

    def _buffers(self, nsig: int, h: int, w: int):
        """This frame's set, the history's set (or None) and the scratch; all are allocated
        again (and the history dropped) when the size or the number of signals changes."""
        if self._key != (nsig, h, w):
            ops = self._ops
            self._key = (nsig, h, w)
            self._sets = [_frame_set(ops, nsig, h, w), _frame_set(ops, nsig, h, w)]
            self._scratch = _scratch(ops, nsig, h, w)
            self._previous = None
        if self._previous is None:
            return 0, None, self._scratch
        return 1 - self._previous, self._sets[self._previous], self._scratch

    def __call__(self, frame, sampler=None) -> np.ndarray:
        """Filter one frame of a sequence; returns (H, W, 3) float32."""
        # below kernels.SERIAL_MAX_PIXELS the CPU backend runs on one thread: each of a frame's ten
        # parallel regions otherwise waits for the pool's threads (see the README)
        with kernels.serial_below(frame.height * frame.width, enabled=self.backend == "cpu"):
            return self._filter(frame)

    def _filter(self, frame) -> np.ndarray:
        p = self.params
        ops = self._ops
        h, w = frame.height, frame.width
        nsig = 2 if (p.separate_lighting and "indirect" in frame) else 1
        if frame.meta.camera_cut:
            self.reset()
        times = {}
        if "motion" not in frame and self._previous is not None and self._key == (nsig, h, w):
            # without motion vectors: those of static geometry from the camera where the frame
            # has its matrices (and depth or position), else spatial only (no history)
            t_motion = time.perf_counter()
            motion = camera_motion(frame, self._jitter)
            times["camera_motion"] = (time.perf_counter() - t_motion) * 1e3
            frame = frame.replace(motion=motion) if motion is not None else frame
        if "motion" not in frame:
            self.reset()
            times = {}
        self._jitter = tuple(float(v) for v in frame.meta.jitter)
        frame = _with_stand_ins(frame)
        index, prev, tmp = self._buffers(nsig, h, w)
        cur = self._sets[index]
        has_prev = prev is not None
        prev = prev if has_prev else cur  # not read without history
        # the colour history: the accumulated colour, or the output of an à-trous iteration
        fb = "acc_sig" if p.feedback_iteration == -1 else "feedback"
        ops.synchronize()
        t_start = t = time.perf_counter()

        def lap(name):
            nonlocal t
            ops.synchronize()
            now = time.perf_counter()
            times[name] = (now - t) * 1e3
            t = now

        color = ops.upload(frame["color"])
        indirect = ops.upload(frame["indirect"]) if nsig == 2 else color
        has_emission = "emission" in frame
        # without the channel a 1x1 stand-in keeps one compiled signature (it is never read)
        emission = ops.upload(frame["emission"] if has_emission else np.zeros((1, 1, 3), np.float32))
        ops.prepare(color, indirect, nsig, emission, has_emission, ops.upload(frame["albedo"]),
                    ops.upload(frame["normal"]), ops.upload(frame["depth"]), ops.upload(frame["object_id"]),
                    ops.upload(frame["motion"]), p.albedo_epsilon, tmp["sig"], tmp["albedo"],
                    cur["valid"], cur["depth"], cur["normal"], cur["obj"], tmp["motion"], tmp["grad"])
        lap("prepare")
        ops.reproject(tmp["sig"], cur["valid"], cur["depth"], cur["normal"], cur["obj"], tmp["grad"],
                      tmp["motion"], prev[fb], prev["mom"], prev["hist"], prev["valid"],
                      prev["depth"], prev["normal"], prev["obj"], has_prev,
                      p.depth_tolerance, p.normal_tolerance, p.alpha_color, p.alpha_moments,
                      bool(p.history_average), p.max_history, cur["acc_sig"], cur["mom"], cur["hist"])
        lap("reprojection")
        ops.variance(cur["mom"], cur["hist"], cur["valid"], cur["depth"], cur["normal"], tmp["grad"],
                     p.variance_frames, p.sigma_z, p.sigma_n, p.depth_epsilon, tmp["var"])
        lap("variance")
        src, var = cur["acc_sig"], tmp["var"]
        for it in range(p.iterations):
            if it == p.feedback_iteration:
                dst = cur["feedback"]
            else:
                dst = tmp["sig_b"] if src is tmp["sig_a"] else tmp["sig_a"]
            var_dst = tmp["var_b"] if var is tmp["var_a"] else tmp["var_a"]
            # the signals of the feedback and the last iteration are read afterwards
            keep = it == p.feedback_iteration or it == p.iterations - 1
            ops.atrous(it, p.iterations, src, var, cur["valid"], cur["depth"], cur["normal"],
                       tmp["grad"], p.sigma_z, p.sigma_n, p.sigma_l, p.depth_epsilon,
                       p.luminance_epsilon, dst, var_dst, keep)
            src, var = dst, var_dst
            lap(f"atrous_{it}")
        out = ops.empty((h, w, 3), np.float32)
        ops.remodulate(src, tmp["albedo"], cur["valid"], color, emission, has_emission, out)
        out = ops.download(out)
        lap("remodulate")
        times["total"] = (time.perf_counter() - t_start) * 1e3 + times.get("camera_motion", 0.0)
        self.stage_ms = times
        self._previous = index
        self._last_variance = tmp["var"]
        return np.ascontiguousarray(out, dtype=np.float32)

    def history_length(self) -> np.ndarray | None:
        """History length (frames) of every pixel after the last call, (H, W) float32."""
        if self._previous is None:
            return None
        return np.array(self._ops.download(self._sets[self._previous]["hist"]), dtype=np.float32)

    def variance_estimate(self) -> np.ndarray | None:
        """Luminance variance of each demodulated signal estimated in the last call, before
        the à-trous iterations: (S, H, W) float64 (temporal, or spatial where history is short).
        """
        if self._last_variance is None:
            return None
        return np.array(self._ops.download(self._last_variance), dtype=np.float64)
