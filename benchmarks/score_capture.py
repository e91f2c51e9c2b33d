"""Score every filter that a captured folder's channels serve, calling the filters directly.

The folder is opened with the ``captured`` plugin (``open_scene``); each filter whose required
channels the capture has runs over the whole sequence (reset before frame 0, so temporal
filters keep their history), on the ``cpu`` backend with default parameters; each frame's
output is scored by the registered ``rmse`` and ``ssim`` metrics against the captured reference.
Filters lacking a channel are listed with the reason. The table holds the mean over frames.

    python benchmarks/score_capture.py CAPTURE_DIR [--filters eaw,svgf]
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from common import names, parser, run

from harness import load_plugins

METRICS = ("rmse", "ssim")


def score(folder, filters=None) -> tuple[pd.DataFrame, dict]:
    """Mean metrics per filter (rows) and the skipped filters with their reasons."""
    registry = load_plugins()
    scene = registry.open_scene(folder)
    renderer = registry.get("renderer", "captured").factory()
    have = set(scene.params["channels"])
    frames = [renderer.render(scene, t, spp=_spp(scene), channels=have) for t in range(scene.frame_count)]
    refs = [renderer.reference(scene, t) for t in range(scene.frame_count)]
    metrics = {m: registry.metrics[m].factory() for m in METRICS}
    rows, skipped = [], {}
    for name, spec in sorted(registry.filters.items()):
        if filters and name not in filters:
            continue
        missing = sorted(spec.requires - have)
        if missing:
            skipped[name] = f"capture lacks {missing}"
            continue
        if "denoise" not in spec.tasks:
            skipped[name] = "not a denoising filter"
            continue
        try:
            filt = spec.factory(backend="cpu", **spec.params)
        except Exception as exc:  # an optional peer missing (e.g. pyoidn)
            skipped[name] = f"cannot build: {exc}"
            continue
        filt.reset()
        scores = {m: [] for m in METRICS}
        for frame, ref in zip(frames, refs):
            visible = frame.subset((spec.requires | spec.optional) & frame.channels)
            out = filt(visible, sampler=None)
            for m, metric in metrics.items():
                scores[m].append(float(metric(out, ref)))
        rows.append({"filter": name, **{m: float(np.mean(v)) for m, v in scores.items()}})
    return pd.DataFrame(rows).set_index("filter"), skipped


def _spp(scene) -> int:
    return scene.params["capture"]["spp"] or 1


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("folder")
    ap.add_argument("--filters", type=names, default=None)
    args = ap.parse_args(argv)
    table, skipped = score(args.folder, args.filters)
    print("| filter | " + " | ".join(table.columns) + " |")
    print("|---|" + "---:|" * len(table.columns))
    for name, row in table.iterrows():
        print(f"| {name} | " + " | ".join(f"{v:.4f}" for v in row) + " |")
    for name, reason in skipped.items():
        print(f"skipped {name}: {reason}")
    return 0


if __name__ == "__main__":
    run(main)
