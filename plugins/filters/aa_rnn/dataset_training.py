"""Training of ``aa_rnn`` on a dataset folder (:mod:`.dataset`) as the paper describes.

Epochs over the training split in batches of ``batch`` (8) whole sequences from a camera cut
(the paper's 7 frames), a random ``crop`` x ``crop`` window of each (the same window in every
frame), turned by a random multiple of 90 degrees and flipped (the flow turned with it),
back-propagating through the recurrence; ``epochs`` (300) epochs. The loss is the one of
:func:`.train.sequence_loss` (the paper's L1 plus temporal L1 on frame differences, later frames
weighted more: frame t by t + 1), on tone-mapped values. Adam, learning rate 5e-4 with cosine
decay to 1e-5 over the run, gradient norm clipped at 1, He initialisation and a zero head. The
validation L1 of whole sequences (the first ``val_sequences`` of the validation split) is
measured every ``eval_every`` epochs and at the end; the weights of the best are written.

**Checkpoints**: after every epoch, ``OUTPUT.ckpt`` holds the model, the optimiser, the random
generator's state, the epoch, the history and the best weights so far (written whole, then
renamed). A run started again with the same settings continues from it and gives the same
weights as a run never stopped; other settings are an error. ``until_epoch`` stops a run early
(to spend a budget in slices). ``snapshots`` names epochs at which the best weights so far are
also written, as ``OUTPUT-eN.npz`` (the learning curve's training-length axis).

**Reproducibility**: PyTorch runs on one thread; batches, crops and augmentation come from one
seeded NumPy generator, the initialisation from ``torch.manual_seed(seed)``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from . import data as D
from . import dataset as DS
from .network import AARNN, unroll
from .train import _frames, _init, sequence_loss
from .weights import DEFAULT_LAYERS, model_arrays, save_weights

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class EpochConfig:
    """Settings of a training run on a dataset folder (all of them are in the checkpoint).

    ``train_sequences``: use the first N sequences of the training split (None: all), for the
    learning curve's data-size axis.
    """

    layers: int = DEFAULT_LAYERS
    epochs: int = 300
    batch: int = 8
    crop: int = 32
    train_sequences: int | None = None
    val_sequences: int = 128
    eval_every: int = 10
    lr: float = 5e-4
    lr_final: float = 1e-5
    temporal_weight: float = 0.5
    clip_norm: float = 1.0
    snapshots: tuple = ()

    def __post_init__(self):
        if self.layers < 1 or self.epochs < 1 or self.batch < 1 or self.crop < 4 or self.eval_every < 1:
            raise ValueError(f"aa_rnn training: layers, epochs, batch, eval_every must be >= 1 and crop >= 4, got "
                             f"{self.layers}, {self.epochs}, {self.batch}, {self.eval_every}, {self.crop}")
        object.__setattr__(self, "snapshots", tuple(sorted(int(e) for e in self.snapshots)))


def steps_per_epoch(n_train: int, batch: int) -> int:
    """Batches per epoch: every training sequence at most once (the remainder waits for the next)."""
    return max(n_train // batch, 1)


def _windows(rng: np.random.Generator, train: list[np.ndarray], indices, crop: int) -> torch.Tensor:
    windows = []
    for k in indices:
        seq = train[int(k)]
        _, _, h, w = seq.shape
        size = min(crop, h, w)
        y0 = int(rng.integers(0, h - size + 1))
        x0 = int(rng.integers(0, w - size + 1))
        window = seq[:, :, y0:y0 + size, x0:x0 + size]
        windows.append(D.augment(window, int(rng.integers(4)), bool(rng.integers(2))))
    return torch.from_numpy(np.stack(windows))


def evaluate(model: AARNN, sequences: list[np.ndarray], chunk: int = 32) -> float:
    """Mean L1 (tone-mapped) over every frame of whole sequences run from a camera cut."""
    total, count = 0.0, 0
    with torch.no_grad():
        for k in range(0, len(sequences), chunk):
            batch = torch.from_numpy(np.stack(sequences[k:k + chunk]))
            outputs = unroll(model, _frames(batch))
            for t, out in enumerate(outputs):
                total += float(torch.sum(torch.abs(out - batch[:, t, 9:12]), dtype=torch.float64))
                count += out.numel()
    return total / max(count, 1)


def _digest(sequences: list[np.ndarray], settings: dict) -> str:
    return D.dataset_digest(sequences, settings)


def _save_checkpoint(path: Path, state: dict) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    torch.save(state, tmp)
    os.replace(tmp, path)


def checkpoint_path(output: Path) -> Path:
    return output.with_name(output.name + ".ckpt")


def snapshot_path(output: Path, epoch: int) -> Path:
    return output.with_name(f"{output.stem}-e{epoch}{output.suffix}")


def train_on_dataset(folder, output, seed: int = 0, config: EpochConfig = EpochConfig(),
                     until_epoch: int | None = None, checkpoint=None) -> Path | None:
    """Train on the dataset in ``folder`` and write the best weights to ``output``.

    The checkpoint is ``checkpoint``, by default :func:`checkpoint_path` of ``output``. Returns
    the weights file, or None when ``until_epoch`` stopped the run before the end (the
    checkpoint holds it; call again to go on).
    """
    folder, output = Path(folder), Path(output)
    ckpt = Path(checkpoint) if checkpoint is not None else checkpoint_path(output)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        train, _ = DS.load_split(folder, "train", config.train_sequences)
        val, _ = DS.load_split(folder, "validation", config.val_sequences)
        if not train or not val:
            raise ValueError(f"aa_rnn training: dataset {folder} has {len(train)} training and {len(val)} validation "
                             f"sequences; it needs at least one of each")
        return _fit(folder, output, ckpt, seed, config, train, val, until_epoch)
    finally:
        torch.set_num_threads(threads)


def _fit(folder: Path, output: Path, ckpt: Path, seed: int, config: EpochConfig, train, val,
         until_epoch) -> Path | None:
    settings = {"seed": seed, "config": _jsonable(dataclasses.asdict(config)),
                "training_data_sha256": _digest(train, {"folder_manifest": _manifest_digest(folder)}),
                "validation_data_sha256": _digest(val, {})}
    per_epoch = steps_per_epoch(len(train), config.batch)
    total = per_epoch * config.epochs
    model = AARNN(config.layers)
    opt = torch.optim.Adam(model.parameters(), lr=config.lr)
    if ckpt.is_file():
        state = torch.load(ckpt, weights_only=True)
        if state["settings"] != settings:
            raise ValueError(f"aa_rnn training: checkpoint {ckpt} was made with other settings or data; delete it "
                             f"or choose another --output")
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
        rng = np.random.default_rng()
        rng.bit_generator.state = state["rng"]
        epoch, history, cpu = state["epoch"], state["history"], state["cpu_s"]
        best = dict(state["best"], arrays={k: v.numpy() for k, v in state["best"]["arrays"].items()})
        log.info("aa_rnn training: resumed from %s at epoch %d", ckpt, epoch)
    else:
        torch.manual_seed(seed)
        _init(model)
        rng = np.random.default_rng(seed + 1)
        err = evaluate(model, val)
        epoch, history, cpu = 0, {"val_l1": [[0, 0, err]], "loss": []}, 0.0
        best = {"val_l1": err, "epoch": 0, "arrays": model_arrays(model)}
    t_cpu = time.process_time()
    stop = config.epochs if until_epoch is None else min(int(until_epoch), config.epochs)
    while epoch < stop:
        order = rng.permutation(len(train))
        losses = []
        for k in range(per_epoch):
            step = epoch * per_epoch + k + 1
            lr = config.lr_final + 0.5 * (config.lr - config.lr_final) * (1.0 + math.cos(math.pi * step / total))
            for group in opt.param_groups:
                group["lr"] = lr
            batch = _windows(rng, train, order[k * config.batch:(k + 1) * config.batch], config.crop)
            outputs = unroll(model, _frames(batch))
            loss = sequence_loss(outputs, [batch[:, t, 9:12] for t in range(batch.shape[1])], None, None,
                                 config.temporal_weight)
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), config.clip_norm)
            opt.step()
            losses.append(float(loss.detach()))
        epoch += 1
        history["loss"].append([epoch, float(np.mean(losses))])
        if epoch % config.eval_every == 0 or epoch == config.epochs:
            err = evaluate(model, val)
            history["val_l1"].append([epoch, epoch * per_epoch, err])
            log.info("aa_rnn training: epoch %d/%d (step %d), loss %.5f, validation L1 %.5f", epoch, config.epochs,
                     epoch * per_epoch, history["loss"][-1][1], err)
            if err < best["val_l1"]:
                best = {"val_l1": err, "epoch": epoch, "arrays": model_arrays(model)}
        if epoch in config.snapshots:
            _write(snapshot_path(output, epoch), best, settings, history, epoch, per_epoch,
                   cpu + time.process_time() - t_cpu)
        _save_checkpoint(ckpt, {"settings": settings, "model": model.state_dict(), "optimizer": opt.state_dict(),
                                "rng": rng.bit_generator.state, "epoch": epoch, "history": history,
                                "best": dict(best, arrays={k: torch.from_numpy(v) for k, v in best["arrays"].items()}),
                                "cpu_s": cpu + time.process_time() - t_cpu})
    if epoch < config.epochs:
        return None
    return _write(output, best, settings, history, epoch, per_epoch, cpu + time.process_time() - t_cpu)


def _write(path: Path, best: dict, settings: dict, history: dict, epoch: int, per_epoch: int, cpu: float) -> Path:
    meta = dict(settings, best_epoch=best["epoch"], best_validation_l1=best["val_l1"], epochs_run=epoch,
                steps_per_epoch=per_epoch, steps_run=epoch * per_epoch, validation_l1=history["val_l1"],
                train_cpu_s=round(cpu, 1), torch=torch.__version__, threads=1, recipe="dataset")
    return save_weights(best["arrays"], meta, path)


def _manifest_digest(folder: Path) -> str:
    manifest = DS.read_manifest(folder) or {}
    return hashlib.sha256(json.dumps(manifest.get("config", {}), sort_keys=True).encode()).hexdigest()


def _jsonable(d: dict) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


#: trainer options (``denoise-bench train aa_rnn -o KEY=VALUE``) of the dataset stage (``data_seed``
#: is the dataset's seed, :attr:`.dataset.DatasetConfig.seed`)
DATASET_OPTIONS = {"sequences", "frames", "size", "reference_spp", "mitsuba_share", "data_seed"}
#: ... of where and how it is rendered
RENDER_OPTIONS = {"workers", "executor", "scheduler"}
#: ... of the training stage
TRAIN_OPTIONS = {f.name for f in dataclasses.fields(EpochConfig)} | {"until_epoch"}


def run_options(seed: int, output, options: dict, checkpoint=None) -> Path:
    """``denoise-bench train aa_rnn -o data=DIR [-o stage=dataset] [-o KEY=VALUE ...]``.

    Makes (or finishes) the dataset in ``data`` with the :data:`DATASET_OPTIONS` and the
    :data:`RENDER_OPTIONS` (without dataset options, a folder that holds a dataset is taken as it
    is); then, unless ``stage=dataset``, trains on it with the
    :data:`TRAIN_OPTIONS` and writes the weights to ``output`` (required: the shipped weights
    come from the default recipe, see ``docs/antialias.md``). Returns the weights file, or the
    dataset's manifest with ``stage=dataset`` or when ``until_epoch`` stopped the training early
    (its checkpoint is then ``checkpoint``, by default the file beside ``output``).
    """
    if not logging.getLogger().handlers:  # progress on standard error when nothing else set logging up
        logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    options = dict(options)
    folder = options.pop("data", None)
    stage = options.pop("stage", "all")
    known = DATASET_OPTIONS | RENDER_OPTIONS | TRAIN_OPTIONS
    unknown = sorted(set(options) - known)
    if folder is None or unknown or stage not in ("dataset", "all"):
        raise ValueError(f"aa_rnn trainer: options need data=DIR, stage=dataset|all and any of {sorted(known)}; "
                         f"got data={folder!r}, stage={stage!r}" + (f", unknown {unknown}" if unknown else ""))
    if stage == "all" and output is None:
        raise ValueError("aa_rnn trainer: training on a dataset needs --output FILE")
    asked = {("seed" if k == "data_seed" else k): options[k] for k in DATASET_OPTIONS if k in options}
    config = None if not asked and DS.read_manifest(Path(folder)) is not None else DS.DatasetConfig(**asked)
    render = {k: options[k] for k in RENDER_OPTIONS if k in options}
    t_wall = time.perf_counter()
    manifest = DS.generate(folder, config, **render)
    log.info("aa_rnn dataset %s: complete, %d sequences (%s), %.1f CPU minutes of rendering, %.1f MB; this call "
             "%.0f s of wall time", folder, manifest["config"]["sequences"], manifest["splits"],
             manifest["render_cpu_s"] / 60.0, manifest["bytes"] / 1e6, time.perf_counter() - t_wall)
    if stage == "dataset":
        return Path(folder) / "manifest.json"
    train = {k: options[k] for k in TRAIN_OPTIONS if k in options}
    until = train.pop("until_epoch", None)
    ckpt = Path(checkpoint) if checkpoint is not None else checkpoint_path(Path(output))
    path = train_on_dataset(folder, output, seed=seed, config=EpochConfig(**train), until_epoch=until, checkpoint=ckpt)
    return path if path is not None else ckpt


def run_shipped_recipe(seed: int = 0, output=None) -> Path:
    """``denoise-bench train aa_rnn`` without options: the recipe of the shipped weights.

    The options and dataset settings recorded in :data:`.weights.SHIPPED` (the paper-scale
    dataset in ``datasets/cache/aa_rnn-data``, relative to the working directory, made or
    finished first: all its 1900 sequences; then 12 epochs on all its 1140 training sequences);
    the weights go to ``output``, by default the shipped file, and the checkpoint beside the
    dataset folder (not among the shipped files). Says whether the weights equal the shipped
    ones: they do for the shipped seed where the dataset holds the same Mitsuba scenes and the
    software is the same.
    """
    from .weights import DEFAULT_LAYERS, SHIPPED, arrays_digest, load_weights, shipped_weights

    shipped = SHIPPED[DEFAULT_LAYERS]
    if output is None and seed != shipped["seed"]:
        raise ValueError(f"aa_rnn trainer: seed {seed} is not the shipped weights' ({shipped['seed']}); give --output "
                         f"to keep the shipped file")
    options = dict(shipped["recipe"])
    folder = Path(options["data"])
    output = Path(output) if output is not None else shipped_weights(DEFAULT_LAYERS)
    manifest = DS.read_manifest(folder)
    if manifest is None:  # a new folder: the shipped settings, the Mitsuba scenes resolved from those present
        settings = {k: v for k, v in shipped["dataset"].items() if k != "mitsuba"}
        options.update(sequences=settings.pop("sequences"), data_seed=settings.pop("seed"), **settings)
    path = run_options(seed, output, options, checkpoint=folder.parent / f"{output.name}.ckpt")
    made = DS.read_manifest(folder)["config"]
    if made != shipped["dataset"]:
        log.warning("aa_rnn: the dataset in %s was made with %s, not the shipped weights' %s: other training data",
                    folder, made, shipped["dataset"])
    same = arrays_digest(load_weights(path)[0]) == shipped["arrays"]
    log.info("aa_rnn: %s %s the shipped weights (seed %d)", path, "reproduces" if same else "differs from",
             shipped["seed"])
    return path
