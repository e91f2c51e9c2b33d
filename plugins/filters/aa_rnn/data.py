"""Training data of ``aa_rnn``: rendered sequences of the random training scenes, and augmentation.

Every scene of :mod:`.trainscenes` is rendered by the harness's ``raster`` renderer with jitter
on (one shading sample per pixel at the Halton jitter, with the G-buffer) and its 8x8 box SSAA
reference (``reference_spp = 64``, as the benchmark scores against), then turned into the
network's inputs by the same :func:`.network.prepare` as inference. A scene is one float32 array
``(frames, 12, H, W)``: channels :data:`CHANNELS`.
"""

from __future__ import annotations

import hashlib

import numpy as np

from harness import load_plugins

from .trainscenes import make_scene

#: channel layout of a rendered training sequence
CHANNELS = ("u0", "u1", "u2", "n0", "n1", "n2", "z", "flow_x", "flow_y", "ref0", "ref1", "ref2")
REFERENCE_SPP = 64


def render_sequence(seed: int, frames: int, resolution: tuple, renderer=None) -> np.ndarray:
    """The prepared inputs and tone-mapped reference of training scene ``seed``: (F, 12, H, W) float32."""
    if renderer is None:
        renderer = load_plugins().get("renderer", "raster").factory(jitter=True)
    scene = make_scene(seed, frames, resolution)
    rendered = [renderer.render(scene, t, channels={"normal", "depth", "motion"}, resolution=resolution)
                for t in range(frames)]
    refs = [renderer.reference(scene, t, spp=REFERENCE_SPP, resolution=resolution) for t in range(frames)]
    return to_planes(np.stack([f["color"] for f in rendered]), np.stack([f["normal"] for f in rendered]),
                     np.stack([f["depth"] for f in rendered]), np.stack([f["motion"] for f in rendered]),
                     np.array([f.meta.jitter for f in rendered], np.float32), np.stack(refs))


def to_planes(color, normal, depth, motion, jitter, reference) -> np.ndarray:
    """A sequence's network inputs and tone-mapped reference as one (F, 12, H, W) float32 array.

    Parameters
    ----------
    color, normal, reference : array (F, H, W, 3)
    depth : array (F, H, W)
    motion : array (F, H, W, 2)
    jitter : array (F, 2)
        As the ``raster`` renderer gives them; the inputs go through :func:`.network.prepare`, the
        same function as at inference.
    """
    import torch

    from .network import prepare, tonemap

    def tensor(a):
        a = np.asarray(a, np.float32)
        return torch.from_numpy(np.ascontiguousarray(a.reshape(a.shape[:3] + (-1,)).transpose(0, 3, 1, 2)))

    inputs = prepare(tensor(color), tensor(normal), tensor(depth), tensor(motion),
                     torch.from_numpy(np.asarray(jitter, np.float32)))
    planes = torch.cat([inputs["u"], inputs["normal"], inputs["z"], inputs["flow"], tonemap(tensor(reference))], 1)
    return np.ascontiguousarray(planes.numpy(), np.float32)


def dataset_digest(sequences: list[np.ndarray], settings: dict) -> str:
    """SHA-256 over the settings and the bytes of every sequence, in order."""
    h = hashlib.sha256(repr(sorted(settings.items())).encode())
    for seq in sequences:
        h.update(str(seq.shape).encode())
        h.update(np.ascontiguousarray(seq, np.float32).tobytes())
    return h.hexdigest()


def augment(window: np.ndarray, rotations: int, flip: bool) -> np.ndarray:
    """Rotate a (T, 12, S, S) window by ``rotations`` x 90 degrees (counter-clockwise, as
    ``np.rot90``) and flip it left-right, turning the flow vectors with the image.

    A point (x, y) of a W-wide image goes to (y, W - 1 - x) under one rotation, so a flow
    (f_x, f_y) becomes (f_y, -f_x); a left-right flip negates f_x.
    """
    out = np.rot90(window, rotations, axes=(2, 3))
    fx, fy = out[:, 7].copy(), out[:, 8].copy()
    for _ in range(rotations % 4):
        fx, fy = fy, -fx
    out = out.copy()
    out[:, 7], out[:, 8] = fx, fy
    if flip:
        out = out[..., ::-1].copy()
        out[:, 7] = -out[:, 7]
    return np.ascontiguousarray(out, np.float32)
