"""The learning curve of ``aa_rnn``: held-out quality against TAA for growing training sets and
training lengths, trained on the paper-scale dataset (``plugins/filters/aa_rnn/dataset.py``).

    python benchmarks/aa_rnn_curve.py train    --data DIR --out DIR --size N --seed S [--steps 6000 | --epochs E]
                                               [--length-in-name]
    python benchmarks/aa_rnn_curve.py evaluate --data DIR --out DIR [--test-limit N] [--only GLOB]
    python benchmarks/aa_rnn_curve.py report   --out DIR [--plot docs/images/aa_rnn_curve.png]
    python benchmarks/aa_rnn_curve.py versus   --run RUN_DIR [--first aa_rnn --second taa --metric ssim]

``train`` trains one point (the first N sequences of the training split, seed S) with
``dataset_training.train_on_dataset`` (checkpointed: run it again to resume), for ``--epochs``
or for the epochs nearest to ``--steps`` batches of 8, writing ``n{N}-s{S}.npz`` and its
snapshots ``n{N}-s{S}-e{E}.npz`` (the best weights by validation L1 up to epoch E) at a quarter
and a half of the run; ``--length-in-name`` puts the run's epochs R in the names
(``n{N}-s{S}-r{R}.npz``, ``n{N}-s{S}-r{R}-e{E}.npz``), so that runs of other lengths of the same
size and seed can share the folder. ``evaluate`` scores every weights file of the folder not yet
scored, and the baselines (the aliased input, TAA, ``aa_rnn`` with its shipped weights) once, on

* the **test split** of the dataset (every test sequence, whole, from a camera cut): SSIM (the
  harness's ``ssim``), ``temporal_error`` and the ghosting measure of ``antialias.py`` (mean
  sRGB error in the pixels a moving object left during the last 4 frames), means over sequences;
* the three **benchmark scenes** (held out from every dataset), 24 frames at 320x180 from a camera
  cut against 8x8 SSAA, as ``antialias.py quality`` scores them (renders shared with it).

Results go to ``DIR/scores.json`` (several ``evaluate`` processes, each with its own ``--only``,
can share it). ``report`` prints the Markdown tables (mean and range over seeds) and draws the
plot. ``versus`` reads a stored ``denoise-bench run --task antialias`` and prints, per scene and for
the mean over scenes, both filters' scores with 95% bootstrap intervals over seeds and frames and
their paired difference (:mod:`harness.statistics`, as the leaderboard computes them); it exits
with status 1 unless the first filter's mean is above the second's (the AA bar). Everything runs
with one PyTorch thread; run it with ``NUMBA_NUM_THREADS=1`` to run several at once.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
from antialias import GBUFFER, moving_trails, render_scene, trail_masks  # noqa: E402
from common import integer, parser, run, timed_call  # noqa: E402

from harness import Frame, FrameMeta, encode_srgb, load_plugins  # noqa: E402

#: ``n{size}-s{seed}[-r{epochs of the run}][-e{snapshot epoch}].npz``
NAME = re.compile(r"^n(\d+)-s(\d+)(?:-r(\d+))?(?:-e(\d+))?\.npz$")
#: scored once: the aliased input, TAA's defaults and ``aa_rnn`` with its shipped weights
BASELINES = ("noaa", "taa", "aa_rnn")
LABELS = {"noaa": "`noaa`", "taa": "`taa`", "aa_rnn": "`aa_rnn`, the weights shipped when scored"}


def train(args) -> None:
    import logging

    import torch

    from plugins.filters.aa_rnn.dataset_training import EpochConfig, steps_per_epoch, train_on_dataset

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s")
    torch.set_num_threads(1)
    per_epoch = steps_per_epoch(args.size, 8)
    epochs = args.epochs or max(1, round(args.steps / per_epoch))
    config = EpochConfig(layers=args.layers, epochs=epochs, crop=args.crop, train_sequences=args.size,
                         val_sequences=args.val_sequences, eval_every=max(1, epochs // 20),
                         snapshots=tuple(sorted({e for e in (epochs // 4, epochs // 2) if 0 < e < epochs})))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = f"n{args.size}-s{args.seed}" + (f"-r{epochs}" if args.length_in_name else "")
    path = train_on_dataset(args.data, out / f"{name}.npz", seed=args.seed, config=config,
                            until_epoch=args.until_epoch)
    print(path or "stopped early; run again to resume")


def _sequence_frames(arrays: dict) -> list:
    frames = []
    for t in range(arrays["color"].shape[0]):
        channels = {c: arrays[c][t] for c in ("color",) + tuple(GBUFFER)}
        frames.append(Frame(channels, FrameMeta(index=t, jitter=tuple(float(v) for v in arrays["jitter"][t]),
                                                camera_cut=t == 0)))
    return frames


def _score(outs, refs, masks, metrics) -> dict:
    ssim = [float(metrics["ssim"](o, r)) for o, r in zip(outs, refs)]
    ghost = [float(np.abs(encode_srgb(o) - encode_srgb(r))[m].mean()) for o, r, m in zip(outs, refs, masks)
             if m.sum() >= 4]
    return {"ssim": float(np.mean(ssim)), "ssim_per_frame": ssim,
            "temporal_error": float(metrics["temporal_error"](outs, refs)),
            "ghost": float(np.mean(ghost)) if ghost else float("nan")}


class Sets:
    """The evaluation inputs, loaded once: test sequences and benchmark scenes."""

    def __init__(self, registry, data: Path, test_limit: int | None):
        from plugins.filters.aa_rnn import dataset as DS

        _, entries = DS.open_dataset(data, complete=False)
        self.test = []
        for e in [e for e in entries if e["split"] == "test"][:test_limit]:
            if DS.read_meta(DS.sequence_path(data, e["index"])) is None:
                raise FileNotFoundError(f"test sequence {e['index']} is not rendered yet")
            a = DS.read_sequence(DS.sequence_path(data, e["index"]))
            frames = _sequence_frames(a)
            refs = list(a["reference"])
            self.test.append((frames, refs, moving_trails(a["meta"]["moving_objects"], list(a["object_id"]))))
        self.bench = {}
        scenes = sorted(n for n, s in registry.scenes.items() if "antialias" in s.tasks and s.suite)
        for name in scenes:
            scene, frames, refs = render_scene(registry, name, GBUFFER, 64)
            self.bench[name] = (frames, refs, trail_masks(scene, frames))


def _run(factory, frames) -> list:
    f = factory()
    f.reset()
    return [np.array(f(frame), copy=True) for frame in frames]


def score_filter(factory, sets: Sets, metrics) -> dict:
    """Test-split means and per-benchmark-scene scores of one filter configuration."""
    test = [_score(_run(factory, frames), refs, masks, metrics) for frames, refs, masks in sets.test]
    out = {"test": {k: float(np.nanmean([t[k] for t in test])) for k in ("ssim", "temporal_error", "ghost")},
           "bench": {}}
    out["test"]["sequences"] = len(test)
    for name, (frames, refs, masks) in sets.bench.items():
        out["bench"][name] = _score(_run(factory, frames), refs, masks, metrics)
    return out


def evaluate(args) -> None:
    import numba
    import torch

    numba.set_num_threads(1)
    torch.set_num_threads(1)
    registry = load_plugins()
    metrics = {m: registry.get("metric", m).factory() for m in ("ssim", "temporal_error")}
    out = Path(args.out)
    path = out / "scores.json"
    scores = json.loads(path.read_text()) if path.is_file() else {}
    sets, wall_ms, _ = timed_call(lambda: Sets(registry, Path(args.data), args.test_limit))
    print(f"inputs: {len(sets.test)} test sequences, {len(sets.bench)} benchmark scenes "
          f"({wall_ms / 1e3:.0f} s)", flush=True)
    todo = [(b, lambda b=b: registry.get("filter", b).factory(backend="cpu")) for b in BASELINES if b not in scores]
    for weights in sorted({w for pattern in args.only or ["*.npz"] for w in out.glob(pattern)}):
        if NAME.match(weights.name) and weights.name not in scores:
            from plugins.filters.aa_rnn.weights import load_weights

            layers = load_weights(weights)[1]["layers"]
            todo.append((weights.name, lambda w=weights, n=layers: registry.get("filter", "aa_rnn").factory(
                backend="cpu", layers=n, weights=str(w))))
    mine = {}
    for key, factory in todo:
        scores[key], _, cpu_ms = timed_call(lambda f=factory: score_filter(f, sets, metrics))
        mine[key] = scores[key]
        if key.endswith(".npz"):
            from plugins.filters.aa_rnn.weights import load_weights

            meta = load_weights(out / key)[1]
            scores[key]["training"] = {k: meta.get(k) for k in ("best_epoch", "epochs_run", "steps_run", "train_cpu_s",
                                                               "best_validation_l1", "seed")}
            scores[key]["training"]["train_sequences"] = meta["config"]["train_sequences"]
        bench = np.mean([v["ssim"] for v in scores[key]["bench"].values()])
        print(f"{key}: test SSIM {scores[key]['test']['ssim']:.4f}, benchmark SSIM {bench:.4f} "
              f"({cpu_ms / 1e3:.0f} CPU s)", flush=True)
        # merged with what other evaluate processes of the folder wrote meanwhile
        merged = dict(json.loads(path.read_text()) if path.is_file() else {}, **mine)
        path.write_text(json.dumps(merged, indent=1, sort_keys=True))


def _points(scores: dict) -> dict:
    """``{(size, run epochs or None, snapshot epoch or None): {seed: scores}}`` of the weights files scored."""
    points: dict = {}
    for key, value in scores.items():
        m = NAME.match(key)
        if m:
            size, seed, length, epoch = int(m.group(1)), int(m.group(2)), m.group(3), m.group(4)
            points.setdefault((size, int(length) if length else None, int(epoch) if epoch else None), {})[seed] = value
    return points


def _bench_mean(value: dict, metric: str) -> float:
    return float(np.mean([v[metric] for v in value["bench"].values()]))


def _fmt(values, digits=4) -> str:
    values = [v for v in values if np.isfinite(v)]
    if not values:
        return "-"
    mean = np.mean(values)
    if len(values) == 1:
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ({min(values):.{digits}f}-{max(values):.{digits}f})"


def report(args) -> None:
    scores = json.loads((Path(args.out) / "scores.json").read_text())
    points = _points(scores)
    scenes = sorted(scores["taa"]["bench"])
    print("| training sequences | epochs (steps) | seeds | test SSIM | test temporal_error | test ghost | "
          "benchmark SSIM | " + " | ".join(scenes) + " | benchmark temporal_error | benchmark ghost | "
          "train CPU min |")
    print("|---" * (10 + len(scenes)) + "|")
    for label in BASELINES:
        v = scores[label]
        print(f"| {LABELS[label]} | - | - | {v['test']['ssim']:.4f} | {v['test']['temporal_error']:.4f} | "
              f"{v['test']['ghost']:.4f} | {_bench_mean(v, 'ssim'):.4f} | "
              + " | ".join(f"{v['bench'][s]['ssim']:.4f}" for s in scenes)
              + f" | {_bench_mean(v, 'temporal_error'):.4f} | {_bench_mean(v, 'ghost'):.4f} | - |")
    for (size, _, _), seeds in sorted(points.items(),
                                      key=lambda kv: (kv[0][0], next(iter(kv[1].values()))["training"]["steps_run"])):
        runs = list(seeds.values())
        tr = runs[0]["training"]
        steps = tr["steps_run"]
        print(f"| {size} | {tr['epochs_run']} ({steps}) | {len(runs)} | "
              f"{_fmt([r['test']['ssim'] for r in runs])} | {_fmt([r['test']['temporal_error'] for r in runs])} | "
              f"{_fmt([r['test']['ghost'] for r in runs])} | {_fmt([_bench_mean(r, 'ssim') for r in runs])} | "
              + " | ".join(_fmt([r["bench"][s]["ssim"] for r in runs]) for s in scenes)
              + f" | {_fmt([_bench_mean(r, 'temporal_error') for r in runs])} | "
              f"{_fmt([_bench_mean(r, 'ghost') for r in runs])} | "
              f"{_fmt([r['training']['train_cpu_s'] / 60.0 for r in runs], 1)} |")
    if args.plot:
        _plot(scores, points, Path(args.plot))


def _plot(scores: dict, points: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, where, title in ((axes[0], "test", "test split (7-frame crops)"),
                             (axes[1], "bench", "benchmark scenes (mean of 3)")):
        def value(v, where=where):
            return v["test"]["ssim"] if where == "test" else _bench_mean(v, "ssim")

        # one line per training length: the sizes' runs of equal step budgets have different epoch
        # counts, so their snapshots (a quarter, a half, the end) are grouped by steps (to 100); a
        # length that only one size reached is a lone marker
        lines: dict = {}
        for (size, _, _), runs in points.items():
            steps = int(round(next(iter(runs.values()))["training"]["steps_run"], -2))
            lines.setdefault(steps, {})[size] = [value(r) for r in runs.values()]
        for steps, by_size in sorted(lines.items()):
            xs = sorted(by_size)
            ys = [float(np.mean(by_size[x])) for x in xs]
            lo = [y - min(by_size[x]) for x, y in zip(xs, ys)]
            hi = [max(by_size[x]) - y for x, y in zip(xs, ys)]
            ax.errorbar(xs, ys, yerr=[lo, hi], marker="o", capsize=3, label=f"about {steps} steps of batch 8")
        for label, style in (("taa", "--"), ("noaa", ":"), ("aa_rnn", "-.")):
            if label in scores:
                ax.axhline(value(scores[label]), color="k", linestyle=style, label=LABELS[label].replace("`", ""))
        ax.set_xscale("log")
        sizes = sorted({size for size, _, _ in points})
        ax.set_xticks(sizes, [str(size) for size in sizes])
        ax.minorticks_off()
        ax.set_xlabel("training sequences (7 frames each)")
        ax.set_ylabel("SSIM against 8x8 SSAA")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(path)


def _cells(df, name: str, metric: str, scene: str | None = None):
    from harness.statistics import CELL_KEYS

    rows = df[(df["filter"] == name) & (df.status == "ok")]
    if scene is not None:
        rows = rows[rows.scene == scene]
    return rows[[*CELL_KEYS, metric]].dropna(subset=[metric]).rename(columns={metric: "value"})


def _p_value(p: float) -> str:
    from harness.statistics import RESAMPLES

    return f"<{1.0 / RESAMPLES:.0e}" if p == 0.0 else f"{p:.2g}"


def versus(args) -> int:
    from harness.results import read_results
    from harness.statistics import interval, paired

    df = read_results(args.run)
    df = df[df.task == "antialias"]
    for name in (args.first, args.second):
        if _cells(df, name, args.metric).empty:
            raise ValueError(f"{args.run}: no ok rows of filter {name!r} with metric {args.metric!r} on task antialias")
    scenes = sorted(set(_cells(df, args.first, args.metric).scene) & set(_cells(df, args.second, args.metric).scene))
    first, second = f"`{args.first}`", f"`{args.second}`"
    print(f"| scene | {first} {args.metric} [95%] | {second} {args.metric} [95%] | {first} - {second} [95%] | p | "
          "frames x seeds |")
    print("|---|---|---|---|---|---|")

    def row(label, a, b):
        ia, ib, d = interval(a), interval(b), paired(a, b)
        print(f"| {label} | {ia.mean:.4f} [{ia.low:.4f}, {ia.high:.4f}] | {ib.mean:.4f} [{ib.low:.4f}, {ib.high:.4f}] "
              f"| {d.difference:+.4f} [{d.low:+.4f}, {d.high:+.4f}] | {_p_value(d.p_value)} | {d.cells} |")
        return ia.mean, ib.mean

    for scene in scenes:
        row(scene, _cells(df, args.first, args.metric, scene), _cells(df, args.second, args.metric, scene))
    keep = lambda c: c[c.scene.isin(scenes)]  # noqa: E731
    a, b = row("mean of the scenes", keep(_cells(df, args.first, args.metric)),
               keep(_cells(df, args.second, args.metric)))
    ok = a > b
    print(f"\nbar: {args.first}'s mean {args.metric} {a:.4f} {'above' if ok else 'not above'} {args.second}'s {b:.4f} "
          f"on {len(scenes)} scenes: {'pass' if ok else 'fail'}")
    return 0 if ok else 1


def main(argv=None) -> int:
    ap = parser(__doc__)
    sub = ap.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train")
    t.add_argument("--data", required=True)
    t.add_argument("--out", required=True)
    t.add_argument("--size", type=integer(1), required=True, help="training sequences (the first N of the split)")
    t.add_argument("--seed", type=integer(0), default=0)
    t.add_argument("--steps", type=integer(1), default=6000, help="batches of 8 to train for (rounded to whole epochs)")
    t.add_argument("--epochs", type=integer(1), default=None, help="epochs instead of --steps (the paper: 300)")
    t.add_argument("--crop", type=integer(4), default=32)
    t.add_argument("--layers", type=integer(1), default=2)
    t.add_argument("--val-sequences", type=integer(1), default=64)
    t.add_argument("--until-epoch", type=integer(1), default=None)
    t.add_argument("--length-in-name", action="store_true",
                   help="name the files n{N}-s{S}-r{epochs}[...]: runs of other lengths of one size and seed apart")
    e = sub.add_parser("evaluate")
    e.add_argument("--data", required=True)
    e.add_argument("--out", required=True)
    e.add_argument("--test-limit", type=integer(1), default=None, help="score the first N test sequences only")
    e.add_argument("--only", action="append", default=None, metavar="GLOB",
                   help="score the weights files of the folder matching this pattern only (repeatable)")
    r = sub.add_parser("report")
    r.add_argument("--out", required=True)
    r.add_argument("--plot", default=None)
    v = sub.add_parser("versus")
    v.add_argument("--run", required=True, help="the output folder of a denoise-bench run --task antialias")
    v.add_argument("--first", default="aa_rnn")
    v.add_argument("--second", default="taa")
    v.add_argument("--metric", default="ssim", help="a metric where higher is better")
    args = ap.parse_args(argv)
    return {"train": train, "evaluate": evaluate, "report": report, "versus": versus}[args.command](args) or 0


if __name__ == "__main__":
    run(main)
