"""The recurrent G-buffer anti-aliasing network and its per-frame step (PyTorch).

One step at frame ``t`` (the same code in training and inference):

1. **inputs** (:func:`prepare`): the aliased colour tone-mapped per channel, ``u = x / (1 + x)``;
   the normals; inverse depth ``z = 1 / depth`` (0 on background); the flow that fetches the
   previous output for the pixel centre, ``motion - jitter`` on surfaces and ``motion`` on
   background (the harness's motion follows the jittered sample on surfaces).
2. **history** (:func:`warp`): the network's own previous output (tone-mapped) resampled
   bilinearly at ``pixel + flow``: the paper's "resampled temporal data", which is also the
   recurrent state. Where the position falls outside the image, and after a reset or a camera
   cut, the history is the current colour.
3. **features** (:func:`features`), ten channels that all vanish on a constant frame: local colour
   contrast ``(u - mean3x3 u) / g``, history minus current ``(h - u) / g``, normal contrast
   ``n - mean3x3 n`` and relative inverse-depth contrast ``(z - mean3x3 z) / mean3x3 z``; ``g``
   is the largest tone-mapped value in the pixel's 3x3 neighbourhood and its history (a local
   contrast normalisation; 0 where everything is black).
4. **network** (:class:`AARNN`): ``layers`` 3x3 convolutions with 32 channels and ReLU, then one
   3x3 convolution to three channels, ``r``; no biases and zero padding.
5. **output**: ``u' = clamp(u + g r, 0, U_MAX)``, returned as ``x' = u' / (1 - u')``; ``u'`` is the
   next frame's history.

Departures from the paper, and why: the network predicts a correction of the current colour in
units of the local contrast, and has no biases (a "bias-free" CNN, Mohan et al., ICLR 2020).
With features that vanish on flat input this makes a constant image stay exactly constant and a
black image stay black, whatever the weights, which the harness's conformance checks require,
and makes the filter independent of the exposure of flat regions. The colour is tone-mapped so
that HDR highlights do not dominate training; radiance above ``1 / (1 - U_MAX)`` (about 1e6)
saturates.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

#: channels of :func:`features`
N_FEATURES = 10
#: width of the hidden layers (the paper's 32)
WIDTH = 32
#: largest tone-mapped value: x = u / (1 - u) stays below about 1e6
U_MAX = 1.0 - 2.0**-20
#: contrast normalisation below this scale is zero (the pixel and its history are black)
G_FLOOR = 1e-8


def tonemap(x: torch.Tensor) -> torch.Tensor:
    """``x / (1 + x)`` per channel of non-negative radiance (negative input is clamped to 0)."""
    x = torch.clamp(x, min=0.0)
    return x / (1.0 + x)


def inverse_tonemap(u: torch.Tensor) -> torch.Tensor:
    """``u / (1 - u)``, with ``u`` clamped to ``[0, U_MAX]``."""
    u = torch.clamp(u, 0.0, U_MAX)
    return u / (1.0 - u)


def prepare(color: torch.Tensor, normal: torch.Tensor, depth: torch.Tensor, motion: torch.Tensor,
            jitter: torch.Tensor) -> dict[str, torch.Tensor]:
    """The network's inputs of a batch of frames.

    Parameters
    ----------
    color, normal : Tensor (N, 3, H, W)
        Linear radiance and unit normals (zero on background).
    depth : Tensor (N, 1, H, W)
        View depth, ``inf`` on background.
    motion : Tensor (N, 2, H, W)
        Harness motion (x, y) in pixels.
    jitter : Tensor (N, 2)
        Each frame's sub-pixel jitter (x, y) in pixels.

    Returns
    -------
    dict
        ``u`` (N, 3, H, W) tone-mapped colour, ``normal``, ``z`` (N, 1, H, W) inverse depth and
        ``flow`` (N, 2, H, W): where the pixel centre's surface was in the previous output.
        Normals that are not finite become 0 and all are clamped to [-1, 1].
    """
    # unit normals lie in [-1, 1]; non-finite or out-of-range guide values must not reach the convolutions
    normal = torch.clamp(torch.nan_to_num(normal, nan=0.0, posinf=0.0, neginf=0.0), -1.0, 1.0)
    surface = torch.isfinite(depth) & (depth > 0)
    z = torch.where(surface, 1.0 / torch.where(surface, depth, torch.ones_like(depth)), torch.zeros_like(depth))
    flow = motion - jitter[:, :, None, None] * surface.to(motion.dtype)
    return {"u": tonemap(color), "normal": normal, "z": z, "flow": flow}


def warp(previous: torch.Tensor, flow: torch.Tensor, current: torch.Tensor) -> torch.Tensor:
    """``previous`` resampled bilinearly at ``pixel + flow``; ``current`` where that lies outside.

    Pixel (i, j) is image point (x, y) = (j, i); a position is inside when
    ``-0.5 <= x <= W - 0.5`` and likewise for y (samples beyond the outer pixel centres repeat
    the border pixels).
    """
    n, _, h, w = flow.shape
    ys = torch.arange(h, dtype=flow.dtype, device=flow.device).view(1, h, 1)
    xs = torch.arange(w, dtype=flow.dtype, device=flow.device).view(1, 1, w)
    x = xs + flow[:, 0]
    y = ys + flow[:, 1]
    grid = torch.stack([2.0 * x / max(w - 1, 1) - 1.0, 2.0 * y / max(h - 1, 1) - 1.0], dim=-1)
    sampled = F.grid_sample(previous, grid, mode="bilinear", padding_mode="border", align_corners=True)
    inside = (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
    return torch.where(inside[:, None], sampled, current)


def _mean3(x: torch.Tensor) -> torch.Tensor:
    return F.avg_pool2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), 3, stride=1)


def _max3(x: torch.Tensor) -> torch.Tensor:
    return F.max_pool2d(F.pad(x, (1, 1, 1, 1), mode="replicate"), 3, stride=1)


def features(u: torch.Tensor, history: torch.Tensor, normal: torch.Tensor, z: torch.Tensor):
    """The ten feature channels and the contrast scale ``g`` (N, 1, H, W); see the module docstring."""
    g = torch.maximum(_max3(u.amax(dim=1, keepdim=True)), history.amax(dim=1, keepdim=True))
    inv_g = torch.where(g > G_FLOOR, 1.0 / torch.clamp(g, min=G_FLOOR), torch.zeros_like(g))
    mz = _mean3(z)
    depth_contrast = torch.where(mz > 1e-12, (z - mz) / torch.clamp(mz, min=1e-12), torch.zeros_like(z))
    f = torch.cat([(u - _mean3(u)) * inv_g, (history - u) * inv_g, normal - _mean3(normal), depth_contrast], dim=1)
    return f, g


class AARNN(nn.Module):
    """``layers`` bias-free 3x3 convolutions (32 channels, ReLU) and a 3x3 head to RGB.

    Parameters
    ----------
    layers : int
        Number of hidden 3x3 convolution + ReLU layers (>= 1).
    """

    def __init__(self, layers: int = 4):
        super().__init__()
        if int(layers) < 1:
            raise ValueError(f"aa_rnn: layers must be >= 1, got {layers}")
        self.layers = int(layers)
        convs = [nn.Conv2d(N_FEATURES, WIDTH, 3, padding=1, bias=False)]
        convs += [nn.Conv2d(WIDTH, WIDTH, 3, padding=1, bias=False) for _ in range(self.layers - 1)]
        self.body = nn.ModuleList(convs)
        self.head = nn.Conv2d(WIDTH, 3, 3, padding=1, bias=False)
        #: layout of the activations (inference uses ``torch.channels_last``, faster on CPUs)
        self.memory_format = torch.contiguous_format

    def forward(self, f: torch.Tensor) -> torch.Tensor:
        """The correction ``r`` (N, 3, H, W) of features ``f`` (N, 10, H, W)."""
        f = f.contiguous(memory_format=self.memory_format)
        for conv in self.body:
            f = F.relu(conv(f))
        return self.head(f)

    def step(self, inputs: dict[str, torch.Tensor], state: torch.Tensor | None) -> torch.Tensor:
        """One frame: the tone-mapped output ``u'`` (N, 3, H, W), also the next frame's state.

        ``state`` is the previous tone-mapped output, or None after a reset or camera cut.
        """
        u = inputs["u"]
        history = u if state is None else warp(state, inputs["flow"], u)
        f, g = features(u, history, inputs["normal"], inputs["z"])
        return torch.clamp(u + g * self(f), 0.0, U_MAX)


def unroll(model: AARNN, frames: list[dict[str, torch.Tensor]], state: torch.Tensor | None = None):
    """Run ``model`` over a sequence of prepared frames; returns the list of tone-mapped outputs.

    This is the training graph (back-propagation runs through the whole recurrence).
    """
    outputs = []
    for inputs in frames:
        state = model.step(inputs, state)
        outputs.append(state)
    return outputs
