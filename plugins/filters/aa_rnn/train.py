"""Training of ``aa_rnn`` with PyTorch (imported by the trainer and the filter, never by the harness).

Data: random scenes of :mod:`.trainscenes` (never the benchmark scenes), rendered by
:mod:`.data`, split 3:1:1 into training, validation and test scenes as in the paper.

Schedule: each step takes a batch of 8 windows of 7 consecutive frames (random training scene,
random square crop, random rotation by a multiple of 90 degrees and left-right flip, the flow
turned with the image). All windows of a step start at the same random frame ``b``: the
frames before it run first without gradients from a camera cut (a burn-in, so the window starts
from the network's own history as at inference), then the 7 frames run with back-propagation
through the recurrence. Loss, on tone-mapped values ``u = x / (1 + x)``: per frame
``|u' - u_ref|_1 + 0.5 |(u'_t - u'_{t-1}) - (u_ref,t - u_ref,t-1)|_1`` (the temporal term
compares frame differences, so flicker and lag cost), frames weighted ``t + 1`` (later frames
count more), mean over pixels and channels. Adam (learning rate 5e-4, cosine decay to 1e-5),
gradient norm clipped at 1. The validation L1 of whole sequences is measured every
``eval_every`` steps; the weights of the last step are written, with the step of the lowest
validation L1 recorded beside them (``best_step``). (This recipe made the first shipped weights,
replaced by those of the paper-scale recipe, :mod:`.dataset_training`, which writes the best
epoch's weights; ``docs/antialias.md`` records both.)

Reproducibility: scene seeds, crops, augmentation and batch order come from one seeded NumPy
generator, the weights' initialisation from ``torch.manual_seed``, and PyTorch runs on one
thread, so the same seed gives the same weights on the same machine and software.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from harness import load_plugins

from . import data as D
from .network import AARNN, inverse_tonemap, unroll
from .weights import DEFAULT_LAYERS, WeightsError, arrays_digest, load_weights, model_arrays, save_weights

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainConfig:
    """Sizes of a training run (see :data:`FULL` and :data:`QUICK`)."""

    scenes: int
    frames: int
    resolution: tuple
    crop: int
    steps: int
    batch: int
    window: int
    eval_every: int
    layers: int = DEFAULT_LAYERS
    lr: float = 5e-4
    lr_final: float = 1e-5
    temporal_weight: float = 0.5
    clip_norm: float = 1.0


FULL = TrainConfig(scenes=60, frames=16, resolution=(128, 96), crop=48, steps=1000, batch=8, window=7,
                   eval_every=50)
QUICK = TrainConfig(scenes=5, frames=4, resolution=(32, 24), crop=16, steps=3, batch=2, window=2, eval_every=3)


def split(count: int) -> tuple[range, range, range]:
    """Scene indices of the training, validation and test sets (3:1:1)."""
    n_val = max(count // 5, 1)
    n_test = max(count // 5, 1)
    n_train = count - n_val - n_test
    return range(n_train), range(n_train, n_train + n_val), range(n_train + n_val, count)


def scene_seeds(seed: int, count: int) -> list[int]:
    """The training scenes' seeds drawn from the run's seed."""
    return [int(s) for s in np.random.default_rng(seed).integers(0, 1 << 30, size=count)]


def make_data(seed: int, config: TrainConfig, cache: Path | None = None) -> list[np.ndarray]:
    """Render (or read from ``cache``) every sequence of the run; see :func:`.data.render_sequence`."""
    renderer = load_plugins().get("renderer", "raster").factory(jitter=True)
    sequences = []
    for k, s in enumerate(scene_seeds(seed, config.scenes)):
        path = None
        if cache is not None:
            w, h = config.resolution
            path = Path(cache) / f"aa_rnn_scene{s}_{w}x{h}_{config.frames}f_spp{D.REFERENCE_SPP}.npy"
            if path.is_file():
                sequences.append(np.load(path))
                continue
        seq = D.render_sequence(s, config.frames, config.resolution, renderer)
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            np.save(path, seq)
        sequences.append(seq)
        log.info("aa_rnn data: scene %d/%d (seed %d) rendered", k + 1, config.scenes, s)
    return sequences


def _frames(batch: torch.Tensor) -> list[dict[str, torch.Tensor]]:
    """A (N, T, 12, H, W) tensor as a list of T prepared input dicts."""
    return [{"u": batch[:, t, 0:3], "normal": batch[:, t, 3:6], "z": batch[:, t, 6:7], "flow": batch[:, t, 7:9]}
            for t in range(batch.shape[1])]


def sequence_loss(outputs, refs, previous, previous_ref, temporal_weight: float) -> torch.Tensor:
    """The training loss of a window (see the module docstring)."""
    total = 0.0
    weights = [t + 1.0 for t in range(len(outputs))]
    norm = sum(weights)
    for t, (out, ref) in enumerate(zip(outputs, refs)):
        term = torch.mean(torch.abs(out - ref))
        prev, prev_ref = (outputs[t - 1], refs[t - 1]) if t else (previous, previous_ref)
        if prev is not None:
            term = term + temporal_weight * torch.mean(torch.abs((out - prev) - (ref - prev_ref)))
        total = total + weights[t] / norm * term
    return total


def evaluate(model: AARNN, sequences: list[np.ndarray]) -> float:
    """Mean L1 (tone-mapped) of whole sequences run from a camera cut."""
    errors = []
    with torch.no_grad():
        for seq in sequences:
            batch = torch.from_numpy(seq)[None]
            outputs = unroll(model, _frames(batch))
            errors += [float(torch.mean(torch.abs(o - batch[:, t, 9:12]))) for t, o in enumerate(outputs)]
    return float(np.mean(errors))


def scores(model: AARNN, sequences: list[np.ndarray]) -> dict:
    """Mean SSIM (the harness's ``ssim`` metric) of the aliased input and of the network on whole
    sequences run from a camera cut."""
    ssim = load_plugins().get("metric", "ssim").factory()
    aliased, network = [], []
    with torch.no_grad():
        for seq in sequences:
            batch = torch.from_numpy(seq)[None]
            outputs = unroll(model, _frames(batch))
            for t, out in enumerate(outputs):
                ref = inverse_tonemap(batch[0, t, 9:12]).permute(1, 2, 0).numpy()
                aliased.append(ssim(inverse_tonemap(batch[0, t, 0:3]).permute(1, 2, 0).numpy(), ref))
                network.append(ssim(inverse_tonemap(out[0]).permute(1, 2, 0).numpy(), ref))
    return {"ssim_aliased": float(np.mean(aliased)), "ssim_network": float(np.mean(network))}


def _batch(rng: np.random.Generator, train: list[np.ndarray], config: TrainConfig, start: int) -> torch.Tensor:
    windows = []
    for _ in range(config.batch):
        seq = train[int(rng.integers(len(train)))]
        _, _, h, w = seq.shape
        y0 = int(rng.integers(0, h - config.crop + 1))
        x0 = int(rng.integers(0, w - config.crop + 1))
        window = seq[:start + config.window, :, y0:y0 + config.crop, x0:x0 + config.crop]
        windows.append(D.augment(window, int(rng.integers(4)), bool(rng.integers(2))))
    return torch.from_numpy(np.stack(windows))


def _init(model: AARNN) -> None:
    """He initialisation of the hidden layers and a zero head (the initial network is the identity:
    it returns the aliased input)."""
    with torch.no_grad():
        for conv in model.body:
            torch.nn.init.kaiming_normal_(conv.weight, nonlinearity="relu")
        model.head.weight.zero_()


def fit(model: AARNN, train: list[np.ndarray], val: list[np.ndarray], config: TrainConfig,
        rng: np.random.Generator) -> dict:
    """Train ``model`` in place; returns the history (``best_step``, the step of the lowest validation
    L1, and ``val_l1`` per evaluation). The model keeps the last step's weights."""
    opt = torch.optim.Adam(model.parameters(), lr=config.lr)
    best = (evaluate(model, val), 0)
    history = {"val_l1": [[0, best[0]]]}
    for step in range(1, config.steps + 1):
        lr = config.lr_final + 0.5 * (config.lr - config.lr_final) * (1.0 + math.cos(math.pi * step / config.steps))
        for group in opt.param_groups:
            group["lr"] = lr
        start = int(rng.integers(0, config.frames - config.window + 1))
        batch = _batch(rng, train, config, start)
        frames = _frames(batch)
        refs = [batch[:, t, 9:12] for t in range(batch.shape[1])]
        state = None
        with torch.no_grad():
            for inputs in frames[:start]:
                state = model.step(inputs, state)
        previous, prev_ref = (state, refs[start - 1]) if start else (None, None)
        outputs = unroll(model, frames[start:], state)
        loss = sequence_loss(outputs, refs[start:], previous, prev_ref, config.temporal_weight)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), config.clip_norm)
        opt.step()
        if step % config.eval_every == 0 or step == config.steps:
            err = evaluate(model, val)
            history["val_l1"].append([step, err])
            log.info("aa_rnn step %d: loss %.5f, validation L1 %.5f", step, float(loss.detach()), err)
            if err < best[0]:
                best = (err, step)
    history["best_step"] = best[1]
    return history


def train(seed: int = 0, output=None, quick: bool = False, layers: int | None = None, cache=None,
          config: TrainConfig | None = None) -> Path:
    """Train ``aa_rnn`` on random scenes and write its weights (``denoise-bench train aa_rnn --quick``).

    Parameters
    ----------
    seed : int
        Seeds the scenes, the batches and the initialisation.
    output : path
        Where to write the weights (required: this recipe no longer makes the shipped file).
    quick : bool
        A tiny run (seconds) for tests: :data:`QUICK` instead of :data:`FULL`.
    layers : int, optional
        Hidden layers (default :data:`.weights.DEFAULT_LAYERS`).
    cache : path, optional
        A folder where rendered sequences are kept and reused (same seeds, sizes and renderer).
    config : TrainConfig, optional
        Overrides ``quick``.

    Returns
    -------
    pathlib.Path
        The weights file.
    """
    if output is None:
        raise ValueError("aa_rnn train: give an output file (the shipped weights come from `denoise-bench train "
                         "aa_rnn`, the dataset recipe)")
    config = config or (QUICK if quick else FULL)
    if layers is not None:
        config = dataclasses.replace(config, layers=int(layers))
    output = Path(output)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    try:
        sequences = make_data(seed, config, cache)
        t_data = time.perf_counter() - t_wall
        train_ids, val_ids, test_ids = split(config.scenes)
        train_set = [sequences[k] for k in train_ids]
        val_set = [sequences[k] for k in val_ids]
        test_set = [sequences[k] for k in test_ids]
        torch.manual_seed(seed)
        model = AARNN(config.layers)
        _init(model)
        history = fit(model, train_set, val_set, config, np.random.default_rng(seed + 1))
        result = {"validation": scores(model, val_set), "test": scores(model, test_set)}
    finally:
        torch.set_num_threads(threads)
    arrays = model_arrays(model)
    w, h = config.resolution
    meta = {
        "seed": seed,
        "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(config).items()},
        "training_data_sha256": D.dataset_digest(sequences, {"seed": seed, "frames": config.frames,
                                                              "resolution": f"{w}x{h}",
                                                              "reference_spp": D.REFERENCE_SPP}),
        "scene_seeds": {"train": [scene_seeds(seed, config.scenes)[k] for k in train_ids],
                        "validation": [scene_seeds(seed, config.scenes)[k] for k in val_ids],
                        "test": [scene_seeds(seed, config.scenes)[k] for k in test_ids]},
        "best_step": history["best_step"],
        "validation_l1": history["val_l1"],
        "scores": result,
        "train_wall_s": round(time.perf_counter() - t_wall, 1),
        "train_cpu_s": round(time.process_time() - t_cpu, 1),
        "data_wall_s": round(t_data, 1),
        "torch": torch.__version__,
        "threads": 1,
    }
    same = None
    if output.is_file():
        try:
            same = arrays_digest(load_weights(output)[0]) == arrays_digest(arrays)
        except WeightsError:
            same = False
    save_weights(arrays, meta, output)
    log.info("aa_rnn: wrote %s (best step %d, test SSIM %.4f vs aliased %.4f)%s", output, history["best_step"],
             result["test"]["ssim_network"], result["test"]["ssim_aliased"],
             "" if same is None else (", identical to the file replaced" if same
                                      else ", differs from the file replaced"))
    return output


def main(argv=None) -> None:
    """``python -m plugins.filters.aa_rnn.train --output P [--layers L] [--seed S] [--cache DIR] [--quick]``."""
    import argparse

    parser = argparse.ArgumentParser(description="train the aa_rnn network (any depth)")
    parser.add_argument("--layers", type=int, default=DEFAULT_LAYERS)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output", required=True)
    parser.add_argument("--cache", default=None, help="folder to keep rendered training sequences in")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    print(train(seed=args.seed, output=args.output, quick=args.quick, layers=args.layers, cache=args.cache))


if __name__ == "__main__":
    main()
