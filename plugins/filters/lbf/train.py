"""Training of LBF with PyTorch (imported only by the trainer, never for inference).

The network is trained through the differentiable filter of :mod:`.torch_ref` on

* randomized variants of the ``synthetic`` renderer's procedural scene: random layout (object
  position and size, sky and horizon heights, checker frequency -- never the benchmark scenes'
  value 8), renderer noise scale, samples per pixel, resolution, exposure (light intensity),
  albedo tint of the surfaces (materials) and flips/transposes of the image (camera); a third of
  them without their variance channel (so the spatial estimate is exercised), and
* when the ``pathtracer`` renderer is registered, randomized variants of the built-in mesh
  scenes (:data:`MESH_SCENES`): moved camera and field of view, tinted materials, scaled
  emitters and sun, moved sun; 1-spp inputs against 128-spp references at 80x60, and
* camera crops of the third-party Mitsuba scenes :data:`.real_scenes.TRAIN_SCENES` (classroom,
  living room; tier ``real``), path traced (:mod:`.real_scenes`); without them the full recipe
  stops with :class:`.real_scenes.RealScenesMissing` (exit status 2 from ``denoise-bench``)
  unless ``real=False`` asks for procedural data alone, which the weights' metadata records.

Half of the frames carry the renderer's ``visibility`` channel, half use the stand-in, so the
weights work with either. Loss: relative MSE ``(F - R)^2 / (R^2 + 0.01)``, the real frames'
scaled so that the two groups weigh alike (:func:`_group_scales`). A held-out set of variants
(other seeds and cameras, the same scenes) selects the best step (:func:`_selection_score`);
the held-out scenes :data:`.real_scenes.HELDOUT_SCENES` (sponza) take no part in training or
selection and measure generalisation. Every split's scores are reported in the weights.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from harness import CHANNELS, CameraPath, Scene, load_plugins

from . import kernels as K
from . import real_scenes as RS
from . import torch_ref as TR
from .weights import (
    DEFAULT_WEIGHTS,
    LBFWeights,
    WeightsError,
    arrays_digest,
    load_weights,
    save_weights,
)

log = logging.getLogger(__name__)

#: initial bandwidths (a, c, b_position, b_normal, b_albedo, b_visibility): a 2.5-pixel spatial
#: sigma, a weak colour term, and feature terms reaching D = 1 at a 5 % position change, a
#: normal change of |dn|^2 = 0.1, an albedo change of 0.03 and a visibility change of 0.5
INITIAL_BANDWIDTHS = (0.08, 0.05, 0.04, 1e-3, 3.3e-3, 4e-4)
RELMSE_EPS = 0.01
BENCHMARK_CHECKER = 8


@dataclass(frozen=True)
class TrainConfig:
    """Sizes of a training run (see :data:`FULL` and :data:`QUICK`)."""

    n_train: int
    n_val: int
    resolutions: tuple
    mesh_train: int
    mesh_val: int
    steps: int
    batch: int
    eval_every: int
    lr: float = 0.01
    radius: int = 5
    #: variants per real training scene in the training / selection sets, and per held-out scene
    real_train: int = 0
    real_val: int = 0
    real_test: int = 0


FULL = TrainConfig(n_train=40, n_val=10, resolutions=((64, 48), (96, 72)),
                   mesh_train=12, mesh_val=4, steps=500, batch=4, eval_every=25,
                   real_train=8, real_val=2, real_test=4)
QUICK = TrainConfig(n_train=10, n_val=4, resolutions=((48, 36), (64, 48)),
                    mesh_train=0, mesh_val=0, steps=40, batch=2, eval_every=10)
#: built-in mesh scenes whose randomized variants (camera, materials, lights) join the training
#: data when the ``pathtracer`` renderer is registered; the benchmark scenes themselves never do
MESH_SCENES = ("cornell", "atrium", "courtyard", "street")
MESH_RESOLUTION = (80, 60)
MESH_REFERENCE_SPP = 128


def _variant(rng: np.random.Generator, config: TrainConfig) -> dict:
    """Random parameters of one training frame."""
    sky = float(rng.uniform(0.05, 0.3))
    return {
        "layout": {
            "pattern": "edges",
            "object_start": [float(rng.uniform(0.02, 0.7)), float(rng.uniform(0.15, 0.7))],
            "object_size": float(rng.uniform(0.1, 0.35)),
            "sky_height": sky,
            "horizon": float(rng.uniform(sky + 0.15, 0.85)),
            "checker": int(rng.choice([3, 4, 5, 6, 7, 9, 10, 12, 16])),
        },
        "noise_scale": float(rng.uniform(0.5, 1.5)),
        "spp": int(rng.choice([1, 1, 2, 4])),
        "resolution": tuple(config.resolutions[int(rng.integers(len(config.resolutions)))]),
        "exposure": float(math.exp(rng.uniform(math.log(0.25), math.log(4.0)))),
        "tint": [float(t) for t in rng.uniform(0.5, 1.2, 3)],
        "flip_x": bool(rng.integers(2)),
        "flip_y": bool(rng.integers(2)),
        "transpose": bool(rng.integers(2)),
        "visibility": bool(rng.integers(2)),
        "drop_variance": bool(rng.random() < 1.0 / 3.0),
        "seed": int(rng.integers(1 << 30)),
    }


def _mesh_variant(rng: np.random.Generator, index: int) -> dict:
    """Random changes to a built-in mesh scene: camera, material colours, light strengths."""
    return {
        "scene": MESH_SCENES[index % len(MESH_SCENES)],
        "eye_jitter": [float(x) for x in rng.normal(0.0, 0.08, 3)],
        "target_jitter": [float(x) for x in rng.normal(0.0, 0.04, 3)],
        "fov_scale": float(rng.uniform(0.8, 1.2)),
        "tints": [float(x) for x in rng.uniform(0.6, 1.15, 3 * 64)],
        "light_scale": float(math.exp(rng.uniform(math.log(0.5), math.log(2.0)))),
        "sun_jitter": [float(x) for x in rng.normal(0.0, 0.15, 3)],
        "visibility": bool(rng.integers(2)),
        "seed": int(rng.integers(1 << 30)),
    }


def render_mesh_variant(reg, v: dict) -> dict[str, np.ndarray]:
    """Render a randomized variant of a built-in mesh scene with the path tracer."""
    scene = reg.scenes[v["scene"]].factory()
    cam = scene.camera
    eye, target = cam.eye(0), cam.targets[0]
    dist = float(np.linalg.norm(target - eye))
    scene.camera = CameraPath(positions=eye + dist * np.asarray(v["eye_jitter"]),
                              targets=target + dist * np.asarray(v["target_jitter"]),
                              up=cam.up, fov=cam.fov * v["fov_scale"], near=cam.near, far=cam.far)
    tints = np.asarray(v["tints"]).reshape(-1, 3)
    scene.materials = [
        dataclasses.replace(
            m,
            albedo=tuple(np.clip(np.asarray(m.albedo) * tints[k % len(tints)], 0.0, 0.95)),
            emission=tuple(np.asarray(m.emission) * v["light_scale"]),
        )
        for k, m in enumerate(scene.materials)
    ]
    if scene.sun is not None:
        d = np.asarray(scene.sun.direction) + np.asarray(v["sun_jitter"])
        d[1] = max(d[1], 0.15)
        radiance = tuple(np.asarray(scene.sun.radiance) * v["light_scale"])
        scene.sun = dataclasses.replace(scene.sun, direction=tuple(d), radiance=radiance)
    scene.frame_count = 1
    scene.name = f"lbf-train-{v['scene']}"
    renderer = reg.renderers["pathtracer"].factory()
    frame = renderer.render(scene, 0, spp=1, seed=v["seed"], channels=frozenset(CHANNELS),
                            resolution=MESH_RESOLUTION)
    ref = renderer.reference(scene, 0, spp=MESH_REFERENCE_SPP, seed=v["seed"] + 1,
                             resolution=MESH_RESOLUTION)
    names = ["color", "variance", "albedo", "position", "normal", "spp"]
    names += ["visibility"] if v["visibility"] else []
    data = {name: np.array(frame[name], order="C") for name in names}
    data["ref"] = np.array(ref, np.float32, order="C")
    return data


def render_variant(reg, v: dict) -> dict[str, np.ndarray]:
    """Render one randomized variant and its reference; returns float32 arrays (and ``spp``)."""
    if v["layout"]["checker"] == BENCHMARK_CHECKER:
        raise ValueError("lbf training: a variant must differ from the benchmark scenes")
    scene = Scene(name="lbf-train", kind="procedural", params=v["layout"], source="lbf")
    renderer = reg.renderers["synthetic"].factory(noise_scale=v["noise_scale"])
    frame = renderer.render(scene, 0, spp=v["spp"], seed=v["seed"], channels=frozenset(CHANNELS),
                            resolution=v["resolution"])
    ref = renderer.reference(scene, 0, resolution=v["resolution"])
    fg = (frame["normal"] != 0).any(axis=-1, keepdims=True)
    gain = v["exposure"] * np.where(fg, np.asarray(v["tint"], np.float32), 1.0)
    data = {
        "color": frame["color"] * gain,
        "variance": frame["variance"] * gain * gain * (0.0 if v["drop_variance"] else 1.0),
        "ref": ref * gain,
        "albedo": frame["albedo"] * np.where(fg, np.asarray(v["tint"], np.float32), 1.0),
        "position": frame["position"],
        "normal": frame["normal"],
        "spp": frame["spp"],
    }
    if v["visibility"]:
        data["visibility"] = frame["visibility"]
    for name, a in data.items():
        if v["flip_x"]:
            a = a[:, ::-1]
        if v["flip_y"]:
            a = a[::-1]
        if v["transpose"]:
            a = np.swapaxes(a, 0, 1)
        data[name] = np.array(a, dtype=np.int32 if name == "spp" else np.float32, order="C")
    return data


def make_dataset(seed: int, count: int, config: TrainConfig, mesh_count: int = 0) -> list[dict]:
    """``count`` synthetic and ``mesh_count`` path-traced variants with their features.

    Mesh variants are skipped (with a log message) when no ``pathtracer`` renderer is registered.
    """
    reg = load_plugins()
    rng = np.random.default_rng(seed)
    renders = [render_variant(reg, _variant(rng, config)) for _ in range(count)]
    if mesh_count and "pathtracer" not in reg.renderers:
        log.warning("lbf training: no 'pathtracer' renderer; training on synthetic scenes only")
        mesh_count = 0
    mesh_rng = np.random.default_rng(seed + 7)
    renders += [render_mesh_variant(reg, _mesh_variant(mesh_rng, k)) for k in range(mesh_count)]
    return with_features(renders)


def make_real_dataset(reg, scenes: dict, seed: int, per_scene: int) -> list[dict]:
    """``per_scene`` path-traced camera crops of each loaded real scene, with their features."""
    return with_features(RS.dataset(reg, scenes, seed, per_scene))


def with_features(renders: list[dict[str, np.ndarray]]) -> list[dict]:
    """Training samples: the arrays as tensors, the filter's variance, signals and features."""
    out = []
    for data in renders:
        t = {k: torch.from_numpy(a) for k, a in data.items()}
        with torch.no_grad():
            var, sig, feat = TR.features(t["color"], t["variance"], t["position"], t["normal"],
                                         t["albedo"], t.get("visibility"), t["spp"])
        t["filter_variance"] = var
        t["sig"] = sig.float()
        t["feat"] = feat.float()
        t["arrays"] = data
        out.append(t)
    return out


def data_hash(datasets: list[list[dict]]) -> str:
    """SHA-256 over every array of the training and held-out data."""
    h = hashlib.sha256()
    for ds in datasets:
        for sample in ds:
            for name in sorted(sample["arrays"]):
                a = sample["arrays"][name]
                h.update(name.encode())
                h.update(str(a.shape).encode())
                h.update(a.tobytes())
    return h.hexdigest()


def relmse(x: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    """Relative MSE ``mean((x - r)^2 / (r^2 + 0.01))``."""
    return ((x - ref) ** 2 / (ref * ref + RELMSE_EPS)).mean()


class _Net(torch.nn.Module):
    def __init__(self, mean, std, generator):
        super().__init__()
        self.l1 = torch.nn.Linear(K.N_FEATURES, K.N_HIDDEN)
        self.l2 = torch.nn.Linear(K.N_HIDDEN, K.N_OUT)
        with torch.no_grad():
            for layer in (self.l1, self.l2):
                bound = 1.0 / math.sqrt(layer.in_features)
                layer.weight.uniform_(-bound, bound, generator=generator)
                layer.bias.uniform_(-bound, bound, generator=generator)
            self.l2.weight.mul_(0.1)
            target = torch.tensor(INITIAL_BANDWIDTHS, dtype=torch.float64)
            self.l2.bias.copy_(torch.log(torch.expm1(target)).float())
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        inv = np.where(std > 1e-6, 1.0 / np.maximum(std, 1e-6), 1.0)
        self.register_buffer("inv_std", torch.as_tensor(inv, dtype=torch.float32))

    def forward(self, feat):
        return TR.mlp(feat, self.mean, self.inv_std, self.l1.weight, self.l1.bias,
                      self.l2.weight, self.l2.bias)

    def to_weights(self, std, meta) -> LBFWeights:
        def arr(t):
            return t.detach().numpy().copy()

        return LBFWeights(w1=arr(self.l1.weight), b1=arr(self.l1.bias), w2=arr(self.l2.weight),
                          b2=arr(self.l2.bias), mean=arr(self.mean), std=std, meta=meta)


def _loss(net, sample, radius):
    params = net(sample["feat"])
    out = TR.cross_bilateral(sample["color"], sample["filter_variance"], sample["sig"], params,
                             radius)
    return relmse(out, sample["ref"])


def _losses(net, dataset, radius) -> list[float]:
    with torch.no_grad():
        return [float(_loss(net, s, radius)) for s in dataset]


def _group_scales(proc_train: list[dict], real_train: list[dict]) -> dict[str, float]:
    """Loss factor per group: 1 for procedural frames, mean procedural / mean real input relMSE for real.

    The real frames' 1-spp inputs have about ten times the relMSE of the procedural ones (dark
    interiors, sun patches), so unscaled they would dominate the loss and the step selection;
    scaled, each group counts by the share of its input error left. Without real frames the
    training is that of procedural data alone, unchanged.
    """
    scales = {"procedural": 1.0}
    if real_train:
        noisy = {name: float(np.mean([float(relmse(s["color"], s["ref"])) for s in group]))
                 for name, group in (("procedural", proc_train), ("real", real_train))}
        scales["real"] = noisy["procedural"] / noisy["real"]
    return scales


def _selection_score(losses: list[float], parts: dict[str, slice], scales: dict[str, float]) -> float:
    """Mean over the groups of the selection set of their scaled mean relMSE (lower is better)."""
    means = [float(np.mean([scales[name] * v for v in losses[part]]))
             for name, part in parts.items() if part.stop > part.start]
    return float(np.mean(means))


def _scores(noisy: list[float], initial: list[float], final: list[float], part: slice) -> dict:
    """Mean relMSE of the noisy input, the initial and the final network over ``part`` of a set."""
    return {"frames": len(noisy[part]), "noisy": float(np.mean(noisy[part])),
            "initial": float(np.mean(initial[part])), "final": float(np.mean(final[part]))}


def fit(seed: int = 0, config: TrainConfig = FULL, real: bool = True) -> tuple[LBFWeights, dict]:
    """Render the data, train, and return the best weights (by held-out relMSE) and a report.

    Runs PyTorch on one thread (faster for these small tensors, and the result does not depend
    on the machine's core count).

    Parameters
    ----------
    seed : int
        Seeds the data (variants and noise), the initialisation and the batch order.
    config : TrainConfig
    real : bool
        Include the real scenes the config asks for (False: procedural data only).

    Returns
    -------
    weights : LBFWeights
    report : dict
        ``heldout_relmse`` (noisy input, initial and final network on the selection set),
        ``splits`` (the same per split: procedural, real, held-out scenes), ``group_scales``,
        ``history`` of the selection score, ``training_data_hash``, timings.

    Raises
    ------
    RealScenesMissing
        When ``real`` and the config asks for real scenes that cannot be loaded (before any
        rendering).
    """
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _fit(seed, config, real)
    finally:
        torch.set_num_threads(threads)


def _real_data(reg, seed: int, config: TrainConfig, real: bool) -> tuple[list, list, list, dict]:
    """The real scenes' training, selection and held-out-scene samples and their description."""
    counts = (config.real_train, config.real_val, config.real_test)
    if not real or not any(counts):
        reason = "real=False" if real is False and any(counts) else "the quick recipe"
        return [], [], [], {"used": False, "reason": f"{reason}: procedural data only"}
    train_scenes = RS.load(reg, RS.TRAIN_SCENES)
    test_scenes = RS.load(reg, RS.HELDOUT_SCENES) if config.real_test else {}
    info = {
        "used": True,
        "train": list(train_scenes),
        "heldout": list(test_scenes),
        "scene_sha256": {n: sc.content_hash() for n, sc in {**train_scenes, **test_scenes}.items()},
        "renderer": "pathtracer",
        "resolutions": [list(r) for r in RS.RESOLUTIONS],
        "reference_spp": RS.REFERENCE_SPP,
        "variants_per_scene": {"train": counts[0], "selection": counts[1], "heldout": counts[2]},
    }
    return (make_real_dataset(reg, train_scenes, seed * 1000 + 3, config.real_train),
            make_real_dataset(reg, train_scenes, seed * 1000 + 4, config.real_val),
            make_real_dataset(reg, test_scenes, seed * 1000 + 5, config.real_test), info)


def _description(real_info: dict) -> str:
    text = ("randomized variants of the synthetic renderer's procedural scene and of the built-in "
            "mesh scenes (no benchmark scene or camera)")
    if real_info["used"]:
        text += (f"; camera crops of the real scenes {', '.join(real_info['train'])} path traced "
                 f"(held-out scenes, never trained on: {', '.join(real_info['heldout']) or 'none'})")
    else:
        text += f"; no real scene ({real_info['reason']})"
    return text


def _fit(seed: int, config: TrainConfig, real: bool) -> tuple[LBFWeights, dict]:
    t_start = time.perf_counter()
    cpu_start = time.process_time()
    real_train, real_val, real_test, real_info = _real_data(load_plugins(), seed, config, real)
    proc_train = make_dataset(seed * 1000 + 1, config.n_train, config, config.mesh_train)
    proc_val = make_dataset(seed * 1000 + 2, config.n_val, config, config.mesh_val)
    train_set = proc_train + real_train
    val_set = proc_val + real_val
    parts = {"procedural": slice(0, len(proc_val)), "real": slice(len(proc_val), len(val_set))}
    t_data = time.perf_counter() - t_start
    cpu_data = time.process_time() - cpu_start
    log.info("lbf training data: %d training frames (%d real), %d selection (%d real), %d of held-out "
             "scenes; %.0f s", len(train_set), len(real_train), len(val_set), len(real_val),
             len(real_test), t_data)
    feats = torch.cat([s["feat"].reshape(-1, K.N_FEATURES) for s in train_set]).double()
    mean = feats.mean(0).numpy().astype(np.float32)
    std = feats.std(0).numpy().astype(np.float32)
    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    net = _Net(mean, std, gen)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    order = np.random.default_rng(seed)
    scales = _group_scales(proc_train, real_train)
    for group, name in ((proc_train, "procedural"), (real_train, "real")):
        for sample in group:
            sample["scale"] = scales[name]
    noisy = [float(relmse(s["color"], s["ref"])) for s in val_set + real_test]
    initial = _losses(net, val_set + real_test, config.radius)
    best = (_selection_score(initial, parts, scales), 0, {k: v.clone() for k, v in net.state_dict().items()})
    history = [(0, best[0])]
    for step in range(1, config.steps + 1):
        opt.zero_grad()
        idx = order.choice(len(train_set), size=config.batch, replace=False)
        loss = sum(train_set[i]["scale"] * _loss(net, train_set[i], config.radius) for i in idx) / config.batch
        loss.backward()
        opt.step()
        if step % config.eval_every == 0 or step == config.steps:
            val = _selection_score(_losses(net, val_set, config.radius), parts, scales)
            history.append((step, val))
            log.info("lbf training step %d: train loss %.5f, selection score %.5f",
                     step, loss.item(), val)
            if val < best[0]:
                best = (val, step, {k: v.clone() for k, v in net.state_dict().items()})
    net.load_state_dict(best[2])
    final = _losses(net, val_set + real_test, config.radius)
    selection = slice(0, len(val_set))
    splits = {name: _scores(noisy, initial, final, part) for name, part in parts.items() if part.stop > part.start}
    if real_test:
        splits["heldout_scenes"] = _scores(noisy, initial, final, slice(len(val_set), len(noisy)))
    report = {
        "training_data_hash": data_hash([train_set, val_set, real_test]),
        "heldout_relmse": {k: v for k, v in _scores(noisy, initial, final, selection).items() if k != "frames"},
        "splits": splits,
        "best_step": best[1],
        "group_scales": scales,
        "history": history,
        "data_seconds": t_data,
        "data_cpu_seconds": cpu_data,
        "train_seconds": time.perf_counter() - t_start,
        "train_cpu_seconds": time.process_time() - cpu_start,
    }
    meta = {
        "seed": seed,
        "radius": config.radius,
        "config": {k: (list(map(list, v)) if k == "resolutions" else v)
                   for k, v in config.__dict__.items()},
        "training_data": _description(real_info),
        "real_scenes": real_info,
        "training_data_hash": report["training_data_hash"],
        "heldout_relmse": report["heldout_relmse"],
        "split_relmse": splits,
        "loss_scales": scales,
        "best_step": best[1],
        "selection_history": [[s, round(v, 6)] for s, v in history],
        "data_cpu_seconds": round(report["data_cpu_seconds"], 1),
        "visibility": "mixed: 50% visibility channel, 50% coverage stand-in",
        "torch_version": torch.__version__,
        "train_seconds": round(report["train_seconds"], 1),
        "train_cpu_seconds": round(report["train_cpu_seconds"], 1),
    }
    return net.to_weights(std, meta), report


def train(seed: int = 0, output: str | Path | None = None, quick: bool = False, real: bool = True) -> Path:
    """Train LBF and write its weights file (the ``denoise-bench train lbf`` entry point).

    Parameters
    ----------
    seed : int
        Seed of data, initialisation and batch order; seed 0 reproduces the shipped weights (on
        the same number of threads).
    output : str or Path, optional
        Where to write the ``.npz``; default: the shipped weights file (:data:`DEFAULT_WEIGHTS`;
        the log says whether the new file is identical to the one it replaces).
    quick : bool
        A small run (< 1 minute) for tests and smoke checks, on procedural data only.
    real : bool
        ``denoise-bench train lbf -o real=false``: leave out the real scenes (the weights'
        metadata says so); by default the full recipe needs them and stops where they are absent.

    Returns
    -------
    Path
        The weights file written.

    Raises
    ------
    RealScenesMissing
        The real scenes are absent (a ``FileNotFoundError``: one line, exit status 2 from the CLI).
    """
    if not isinstance(real, bool):
        raise ValueError(f"lbf trainer: option real must be true or false, got {real!r}")
    config = QUICK if quick else FULL
    weights, report = fit(seed, config, real)
    weights.meta["quick"] = bool(quick)
    target = Path(output) if output is not None else DEFAULT_WEIGHTS
    previous = _digest(target)
    path = save_weights(weights, target)
    log.info("lbf: wrote %s in %.1f s (held-out relMSE %.4f -> %.4f; same weights as the file it "
             "replaced: %s)", path, report["train_seconds"], report["heldout_relmse"]["initial"],
             report["heldout_relmse"]["final"], previous == arrays_digest(weights.arrays()))
    return path


def _digest(path: Path) -> str | None:
    """The array checksum of an existing weights file, or None."""
    try:
        return load_weights(path).meta["arrays_sha256"]
    except WeightsError:
        return None
