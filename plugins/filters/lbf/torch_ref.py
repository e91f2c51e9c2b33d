"""LBF in PyTorch: features, network and a filter differentiable in its bandwidths.

Used by the trainer (:mod:`.train`) and by the tests as the reference that the Numba inference
must match. Nothing on the inference path imports this module. Every function is
dtype-generic (float64 for reference checks, float32 for training) and mirrors
:mod:`.kernels` operation for operation: clamped (replicated) borders for the statistics,
skipped out-of-image taps in the filter.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from .features import FEATURE_VAR_FLOOR
from .kernels import HAAR_MAD, VAR_MAX, VAR_RADIUS, Z_CLAMP

_GROUPS = ((0, 3), (3, 6), (6, 9), (9, 12), (12, 13))


def _pad(x: torch.Tensor, r: int) -> torch.Tensor:
    """Replicate-pad (C, H, W) by ``r`` on every side."""
    return F.pad(x[None], (r, r, r, r), mode="replicate")[0]


def _box(x: torch.Tensor, r: int) -> torch.Tensor:
    """Mean over (2r+1)^2 windows with clamped borders, (C, H, W) -> (C, H, W)."""
    return F.avg_pool2d(_pad(x, r)[None], 2 * r + 1, stride=1)[0]


def _neighbours(x: torch.Tensor) -> torch.Tensor:
    """The 3x3 clamped neighbourhood of each pixel, (C, H, W) -> (9, C, H, W), row-major."""
    h, w = x.shape[-2:]
    p = _pad(x, 1)
    return torch.stack([p[:, di:di + h, dj:dj + w] for di in range(3) for dj in range(3)])


def position_stats(position: torch.Tensor, normal: torch.Tensor) -> tuple[torch.Tensor, float]:
    """Mean and RMS spread of foreground positions, as :func:`.features.position_stats`."""
    p = position.double().reshape(-1, 3)
    fg = (normal.reshape(-1, 3) != 0).any(dim=1)
    if not bool(fg.any()):
        return torch.zeros(3, dtype=torch.float64), 1.0
    q = p[fg]
    mu = q.mean(dim=0)
    scale = float(torch.sqrt(((q - mu) ** 2).sum(dim=1).mean()))
    if not scale > 1e-12 or scale == float("inf"):
        scale = 1.0
    return mu, scale


def signals(color, variance, position, normal, albedo, vis=None, spp=None):
    """Signals (H, W, 13) and aux (H, W, 3) of a frame; inputs (H, W, 3) / (H, W) tensors."""
    dt = torch.float64
    c = color.to(dt).clamp_min(0.0)
    fg = (normal != 0).any(dim=-1).to(dt)
    mu, scale = position_stats(position, normal)
    pos = (position.to(dt) - mu) / scale
    v = vis.to(dt) if vis is not None else fg
    sig = torch.cat([torch.log1p(c), pos, normal.to(dt), albedo.to(dt), v[..., None]], dim=-1)
    s = torch.sqrt((variance.to(dt).clamp_min(0.0) / (1.0 + c) ** 2).sum(-1) / 3.0)
    inv_spp = 1.0 / spp.to(dt).clamp_min(1.0) if spp is not None else torch.ones_like(s)
    aux = torch.stack([s, fg, inv_spp], dim=-1)
    return sig, aux


def secondary_features(sig: torch.Tensor, aux: torch.Tensor) -> torch.Tensor:
    """The 36 secondary features (H, W, 36) from float64 signals, as :func:`.kernels.combine_px`."""
    x = sig.permute(2, 0, 1)
    a = aux.permute(2, 0, 1)
    m7, q7 = _box(x, 3), _box(x * x, 3)
    m3, q3 = _box(x, 1), _box(x * x, 1)
    var7 = (q7 - m7 * m7).clamp_min(0.0)
    var3 = (q3 - m3 * m3).clamp_min(0.0)
    nb = _neighbours(x)
    mad = (nb - x[None]).abs().mean(dim=0)
    p = _pad(x, 1)
    h, w = x.shape[-2:]
    gx = 0.5 * (p[:, 1:h + 1, 2:] - p[:, 1:h + 1, :w])
    gy = 0.5 * (p[:, 2:, 1:w + 1] - p[:, :h, 1:w + 1])
    grad2 = gx * gx + gy * gy
    means = torch.stack([x[g0:g1].mean(0) for g0, g1 in _GROUPS])
    pr = F.pad(means[None], (0, 1, 0, 1), mode="replicate")[0]
    hh = (0.5 * (pr[:, :h, :w] - pr[:, :h, 1:] - pr[:, 1:, :w] + pr[:, 1:, 1:])).abs()
    noise = _neighbours(hh).median(dim=0).values / HAAR_MAD
    std7 = torch.stack([var7[g0:g1].mean(0).sqrt() for g0, g1 in _GROUPS])
    std3 = torch.stack([var3[g0:g1].mean(0).sqrt() for g0, g1 in _GROUPS])
    mad_g = torch.stack([mad[g0:g1].mean(0) for g0, g1 in _GROUPS])
    grad_g = torch.stack([grad2[g0:g1].sum(0).sqrt() for g0, g1 in _GROUPS])
    aux7 = _box(a[:2], 3)
    s = a[0]
    rest = torch.stack([
        m7[0:3].mean(0), m7[9:12].mean(0), m7[12],
        x[0:3].mean(0), x[9:12].mean(0), x[12],
        s, aux7[0], s / (std7[0] + 1e-3),
        a[2], aux7[1],
    ])
    return torch.cat([std7, std3, mad_g, grad_g, noise, rest]).permute(1, 2, 0).contiguous()


def effective_variance(color, variance):
    """The variance, or (when it is zero everywhere) the colour's clamped 5x5 variance, float32."""
    if bool((variance > 0).any()):
        return variance.float()
    c = color.double().permute(2, 0, 1)
    m = _box(c, VAR_RADIUS)
    v = (_box(c * c, VAR_RADIUS) - m * m).clamp(0.0, VAR_MAX)
    return v.permute(1, 2, 0).float()


def features(color, variance, position, normal, albedo, vis=None, spp=None):
    """Effective variance (H, W, 3), signals (H, W, 13) and secondary features (H, W, 36).

    As the CPU backend (:class:`.cpu.Denoiser` with ``keep``); signals and features are float64.
    """
    variance = effective_variance(color, variance)
    sig, aux = signals(color, variance, position, normal, albedo, vis, spp)
    return variance, sig, secondary_features(sig, aux)


def mlp(feat, mean, inv_std, w1, b1, w2, b2):
    """Bandwidths (H, W, 6) from raw features (H, W, 36): z-normalise, clamp, sigmoid, softplus."""
    z = ((feat - mean) * inv_std).clamp(-Z_CLAMP, Z_CLAMP)
    hidden = torch.sigmoid(z @ w1.T + b1)
    return F.softplus(hidden @ w2.T + b2)


def cross_bilateral(color, variance, sig, params, radius: int):
    """The filter of :func:`.kernels.filter_px`, differentiable in ``params``.

    Parameters
    ----------
    color, variance : tensor (H, W, 3)
    sig : tensor (H, W, 13)
    params : tensor (H, W, 6)
    radius : int

    Returns
    -------
    tensor (H, W, 3)
    """
    h, w = color.shape[:2]
    dt = params.dtype
    k = 2 * radius + 1
    c = color.to(dt).permute(2, 0, 1)
    v = variance.to(dt).clamp_min(0.0).permute(2, 0, 1)
    f = sig[..., 3:].to(dt).permute(2, 0, 1)

    def patches(t):
        n = t.shape[0]
        return F.unfold(t[None], k, padding=radius)[0].reshape(n, k * k, h * w)

    cj, vj, fj = patches(c), patches(v), patches(f)
    valid = patches(torch.ones(1, h, w, dtype=dt))[0]
    ci = c.reshape(3, 1, h * w)
    vi = v.reshape(3, 1, h * w) + 1e-10
    fi = f.reshape(10, 1, h * w)
    dcol = ((ci - cj) ** 2 / (vi + vj)).sum(0)
    df2 = (fi - fj) ** 2
    dfeat = torch.stack([df2[0:3].sum(0), df2[3:6].sum(0), df2[6:9].sum(0), df2[9]])
    dfeat = dfeat / FEATURE_VAR_FLOOR
    off = torch.arange(k, dtype=dt) - radius
    dsp = (off[:, None] ** 2 + off[None, :] ** 2).reshape(k * k, 1)
    p = params.reshape(h * w, 6).T
    d = p[0] * dsp + p[1] * dcol + (p[2:, None, :] * dfeat).sum(0)
    wt = torch.exp(-d) * valid
    out = (wt[None] * cj).sum(1) / wt.sum(0)
    noisy = (v.sum(0) > 0).reshape(1, h * w)
    out = torch.where(noisy, out, c.reshape(3, h * w))
    return out.T.reshape(h, w, 3)
