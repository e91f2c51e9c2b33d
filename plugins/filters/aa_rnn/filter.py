"""The ``aa_rnn`` filter object: inference of the trained network, frame by frame."""

from __future__ import annotations

import numpy as np

from harness import load_backend

from .weights import DEFAULT_LAYERS, WeightsError, load_weights, shipped_weights

BACKENDS = ("cpu", "cuda")


class AARNNFilter:
    """The recurrent G-buffer anti-aliasing network (inference with ``torch.inference_mode``).

    Parameters
    ----------
    backend : {"cpu", "cuda"}
        Where PyTorch runs the network.
    layers : int
        Hidden layers of the network; selects the shipped weights of that depth.
    weights : str, optional
        A weights file (from ``denoise-bench train aa_rnn --output``) instead of the shipped one;
        its depth must equal ``layers``.

    Notes
    -----
    The recurrent state (the previous output, tone-mapped, on the device) is dropped on
    :meth:`reset`, on a frame whose ``meta.camera_cut`` is set and when the image size changes.
    PyTorch runs with as many threads as Numba (``numba.get_num_threads()``), the harness's
    thread setting.
    """

    def __init__(self, backend: str = "cpu", layers: int = DEFAULT_LAYERS, weights: str | None = None):
        import torch

        from .network import AARNN
        from .weights import load_into

        self._ops = load_backend(__package__, backend, BACKENDS, owner="aa_rnn")
        self.device = self._ops.device()
        path = shipped_weights(layers) if weights is None else weights
        if weights is None and not path.is_file():
            raise WeightsError(f"aa_rnn: no shipped weights for {layers} layers ({path.name}); train them with "
                               f"`denoise-bench train aa_rnn -o data=DIR -o layers={layers} --output FILE` and "
                               f"pass weights=FILE")
        arrays, self.meta = load_weights(path)
        if self.meta["layers"] != layers:
            raise ValueError(f"aa_rnn: weights {path} have {self.meta['layers']} layers, the parameter says {layers}")
        self.model = AARNN(layers)
        load_into(self.model, arrays)
        self.model.eval()
        self.model.memory_format = torch.channels_last
        self.model.to(self.device, memory_format=torch.channels_last)
        self._state = None

    def reset(self) -> None:
        """Forget the recurrent state (new sequence or camera cut)."""
        self._state = None

    def __call__(self, frame, sampler=None) -> np.ndarray:
        """Anti-alias one frame of a sequence; returns (H, W, 3) float32."""
        import numba
        import torch

        from .network import inverse_tonemap, prepare

        if frame.meta.camera_cut or (self._state is not None and tuple(self._state.shape[2:]) != frame.shape):
            self.reset()
        torch.set_num_threads(numba.get_num_threads())

        def planes(name):
            a = np.asarray(frame[name], np.float32)
            a = a.reshape(a.shape[0], a.shape[1], -1)
            return torch.from_numpy(np.array(a, np.float32)).to(self.device).permute(2, 0, 1)[None]

        with torch.inference_mode():
            jitter = torch.tensor([frame.meta.jitter], dtype=torch.float32, device=self.device)
            inputs = prepare(planes("color"), planes("normal"), planes("depth"), planes("motion"), jitter)
            self._state = self.model.step(inputs, self._state)
            out = inverse_tonemap(self._state)[0].permute(1, 2, 0).cpu().numpy()
        return np.ascontiguousarray(out, dtype=np.float32)
