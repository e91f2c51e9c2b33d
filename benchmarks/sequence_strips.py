"""Picture strips of a run's sequences, and how much of each frame moves.

Usage::

    python benchmarks/sequence_strips.py out/i30-classroom [more run folders] [--out docs/images]
                                         [--motion]

For each scene of each run (a ``denoise-bench run ... --report`` folder): one PNG,
``<out>/sequence_<scene>.png``, with a row per image (the reference, the noisy input, each
filter's output) and a column per frame the run kept (the first, the middle and the last), shown
as the report shows them (exposure 1, clamped, sRGB). With ``--motion`` also, for every frame
after the first of the run's frame count, the share of pixels whose motion vector is longer than
0.01 pixels and the median length (the path tracer's G-buffer at the run's resolution, the scene
opened from the folder the run names in its manifest).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
from common import ROOT, parser, run

from harness.report import outputs as stored
from harness.report import pictures


def strip(run: Path, task: str, scene: str) -> tuple[np.ndarray, list[str]] | None:
    """The rows (reference, input, filters) x kept frames of one scene, and the row labels."""
    folder = stored.folder(run, task, scene)
    frames = sorted({int(p.stem.rpartition("-f")[2]) for p in folder.glob("reference-f*.npy")})
    if not frames:
        return None
    names = sorted({p.stem.rpartition("-f")[0] for p in folder.glob("*-f*.npy")} - {"reference"})
    names = [n for n in names if n.startswith("input")] + [n for n in names if not n.startswith("input")]
    rows, labels = [], []
    for name in ["reference", *names]:
        images = [stored.load(run, task, scene, name, t) for t in frames]
        if any(i is None for i in images):
            continue
        rows.append(np.concatenate(images, axis=1))
        labels.append(name.split("-")[0])
    return np.concatenate(rows, axis=0), labels


def motion_shares(run: Path, scene_name: str) -> list[tuple[int, float, float]]:
    """(frame, share of pixels moving more than 0.01 px, median motion in px) for frames 1.. of the run."""
    from harness import load_plugins

    manifest = json.loads((run / "manifest.json").read_text())
    command = manifest["command"].split()
    folder = command[command.index("--scene-dir") + 1]
    registry = load_plugins()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = registry.open_scene(ROOT / folder)
    import pandas as pd

    rows = pd.read_parquet(run / "results.parquet")
    rows = rows[rows.scene == scene_name]
    size = (int(rows.width.iloc[0]), int(rows.height.iloc[0]))
    tracer = registry.get("renderer", "pathtracer").factory()
    out = []
    for t in range(1, int(rows.frame.max()) + 1):
        motion = tracer.render(scene, t, channels={"motion"}, resolution=size)["motion"]
        length = np.linalg.norm(motion, axis=-1)
        out.append((t, float((length > 0.01).mean()), float(np.median(length))))
    return out


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "images")
    ap.add_argument("--motion", action="store_true")
    args = ap.parse_args(argv)
    for folder in args.runs:
        for task_dir in sorted((folder / stored.FOLDER).glob("*")):
            for scene_dir in sorted(task_dir.glob("*")):
                made = strip(folder, task_dir.name, scene_dir.name)
                if made is None:
                    continue
                image, labels = made
                path = args.out / f"sequence_{scene_dir.name}.png"
                pictures.write_display(path, image)
                print(f"{path}: rows {', '.join(labels)}; {image.shape[1]}x{image.shape[0]}")
                if args.motion:
                    for t, share, median in motion_shares(folder, scene_dir.name):
                        print(f"  frame {t}: {100 * share:.1f}% of pixels move, median {median:.2f} px")
    return 0


if __name__ == "__main__":
    run(main)
