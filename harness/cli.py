"""The ``denoise-bench`` command.

Sub-commands: ``run`` (the benchmark), ``plugins`` (what is registered), ``show`` (summary and
leaderboard of a stored run), ``render`` (references into the cache), ``bench`` (per-frame
timing of filters against peers) and ``train`` (learned filters).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from harness.cache import Cache, default_cache_dir
from harness.plugins import PluginConflictError, load_plugins
from harness.specs import SceneSpec

DEFAULT_OUT = Path("out") / "latest"


def _csv(value: str) -> list[str]:
    return [v.strip() for v in value.split(",") if v.strip()]


def _ints(value: str) -> list[int]:
    return [int(v) for v in _csv(value)]


def _resolution(value: str) -> tuple[int, int]:
    try:
        w, h = value.lower().split("x")
        res = (int(w), int(h))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 1280x720, got {value!r}") from None
    if min(res) < 1:
        raise argparse.ArgumentTypeError(f"resolution must be positive, got {value!r}")
    return res


def _param(value: str) -> tuple[str, str, object]:
    try:
        key, raw = value.split("=", 1)
        name, param = key.split(".", 1)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--param must look like FILTER.NAME=VALUE, got {value!r}") from None
    try:
        parsed = json.loads(raw)
    except json.JSONDecodeError:
        parsed = raw
    return name, param, parsed


def _preset(value: str) -> tuple[str, str]:
    if "=" not in value:
        raise argparse.ArgumentTypeError(f"--preset must look like FILTER=PRESET, got {value!r}")
    name, preset = value.split("=", 1)
    return name, preset


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--disable",
        type=_csv,
        default=[],
        metavar="NAMES",
        help="plugins to disable, comma-separated (also $DENOISE_HARNESS_DISABLE)",
    )


def _add_selection(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--scenes",
        type=_csv,
        default=None,
        metavar="NAMES",
        help="scenes to use, comma-separated (default: the built-in suite)",
    )
    p.add_argument(
        "--scene-dir",
        action="append",
        default=[],
        metavar="PATH",
        help="also use the scene stored in this folder (e.g. a Mitsuba XML scene); repeatable",
    )
    p.add_argument(
        "--renderer", default=None, help="renderer for every scene (default: the preferred one per scene kind)"
    )
    p.add_argument(
        "--resolution", type=_resolution, default=None, metavar="WxH", help="override every scene's resolution"
    )
    p.add_argument("--frames", type=int, default=None, help="at most this many frames per scene")
    p.add_argument(
        "--cache-dir",
        type=Path,
        default=None,
        help=f"render cache (default: $DENOISE_HARNESS_CACHE or {default_cache_dir()})",
    )
    p.add_argument("--no-cache", action="store_true", help="neither read nor write the render cache")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="denoise-bench", description="Benchmark real-time Monte Carlo denoising filters."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="render the scenes, run every filter, score and time them")
    _add_selection(run)
    run.add_argument("--filters", type=_csv, default=None, metavar="NAMES", help="filters to run (default: all)")
    run.add_argument("--metrics", type=_csv, default=None, metavar="NAMES", help="metrics to score (default: all)")
    run.add_argument(
        "--backend",
        type=_csv,
        default=["auto"],
        metavar="B",
        help="cpu, cuda, auto (cuda where a GPU is present) or all; comma-separated",
    )
    run.add_argument("--spp", type=_ints, default=[1], metavar="N", help="samples per pixel of the noisy input (list)")
    run.add_argument("--seeds", type=_ints, default=[0], metavar="S", help="seeds of the noisy input (list)")
    run.add_argument(
        "--reference-spp", type=int, default=None, help="samples per pixel of references (default: the renderer's)"
    )
    run.add_argument(
        "--param",
        type=_param,
        action="append",
        default=[],
        metavar="FILTER.NAME=VALUE",
        help="set a filter parameter (JSON value); repeatable",
    )
    run.add_argument(
        "--preset",
        type=_preset,
        action="append",
        default=[],
        metavar="FILTER=PRESET",
        help="use a filter's named parameter preset; repeatable",
    )
    run.add_argument("--repeats", type=int, default=3, help="timed calls per frame (default 3)")
    run.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    run.add_argument("--csv", action="store_true", help="also write results.csv")
    run.add_argument("--pictures", action="store_true", help="write PNGs of every filter's first frame")
    run.add_argument("--resume", action="store_true", help="keep jobs already stored in --out, run the rest")
    run.add_argument("--strict", action="store_true", help="exit non-zero if any job errored")
    run.add_argument(
        "--nonfinite",
        choices=["raise", "repair"],
        default="raise",
        help="NaN/Inf in renderer output: fail the render (raise) or replace and count (repair)",
    )
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_common(run)

    plugins = sub.add_parser("plugins", help="list every plugin with its declarations and status")
    plugins.add_argument("--format", choices=["table", "json"], default="table")
    _add_common(plugins)

    show = sub.add_parser("show", help="summary table and leaderboard of a stored run")
    show.add_argument("dir", type=Path)
    show.add_argument("--all", action="store_true", help="print every row, not the summary")
    show.add_argument(
        "--markdown",
        type=Path,
        default=None,
        metavar="FILE",
        help="also write the summary and leaderboard as markdown to FILE",
    )
    _add_common(show)

    render = sub.add_parser("render", help="render references into the cache (chunked, resumable)")
    _add_selection(render)
    render.add_argument("--spp", type=int, default=None, help="reference samples per pixel (default: the renderer's)")
    render.add_argument("--chunk", type=int, default=64, help="samples per chunk between checkpoints")
    _add_common(render)

    bench = sub.add_parser("bench", help="time filters per frame against peers in the same process")
    bench.add_argument("filters", type=_csv, help="filter(s) to time, comma-separated")
    bench.add_argument(
        "--peers",
        type=_csv,
        default=None,
        metavar="NAMES",
        help="peer filters timed on the same frame (default: opencv_jbf,oidn where registered)",
    )
    bench.add_argument("--scene", default="synthetic-edges")
    bench.add_argument("--renderer", default=None)
    bench.add_argument("--resolution", type=_csv, default=["1280x720", "1920x1080"], metavar="WxH,...")
    bench.add_argument("--backend", default="cpu")
    bench.add_argument("--repeats", type=int, default=10)
    bench.add_argument("--param", type=_param, action="append", default=[], metavar="FILTER.NAME=VALUE")
    bench.add_argument("--preset", type=_preset, action="append", default=[], metavar="FILTER=PRESET")
    bench.add_argument("--cache-dir", type=Path, default=None)
    _add_common(bench)

    train = sub.add_parser("train", help="train a learned filter and write its weights")
    train.add_argument("filter")
    train.add_argument("--seed", type=int, default=0)
    train.add_argument(
        "--output", type=Path, default=None, help="weights file (default: the filter's shipped location)"
    )
    train.add_argument("--quick", action="store_true", help="a short run (minutes) for smoke tests")
    _add_common(train)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``denoise-bench``; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        registry = load_plugins(disable=args.disable)
    except PluginConflictError as exc:
        print(f"denoise-bench: {exc}", file=sys.stderr)
        return 2
    from harness import commands

    handler = getattr(commands, f"cmd_{args.command}")
    try:
        return handler(registry, args)
    except (KeyError, ValueError, FileNotFoundError) as exc:
        message = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
        print(f"denoise-bench {args.command}: {message}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            f"\ndenoise-bench {args.command}: interrupted; stored results are kept (rerun with --resume)",
            file=sys.stderr,
        )
        return 130


def scene_selection(registry, args) -> tuple[list[SceneSpec], dict]:
    """Scene specs of ``--scenes`` (or the suite) plus scenes opened from ``--scene-dir``."""
    if args.scenes is None and not args.scene_dir:
        specs = [s for _, s in sorted(registry.scenes.items()) if s.suite]
    else:
        specs = [registry.get("scene", n) for n in (args.scenes or [])]
    opened = {}
    for folder in args.scene_dir:
        scene = registry.open_scene(folder)
        opened[scene.name] = scene
        specs.append(
            SceneSpec(
                name=scene.name,
                version="folder",
                factory=lambda s=scene: s,
                tags=scene.tags,
                frames=scene.frame_count,
                resolution=scene.resolution,
                kind=scene.kind,
                suite=False,
            )
        )
    if not specs:
        raise ValueError("no scenes selected")
    return specs, opened


def make_cache(args) -> Cache:
    return Cache(args.cache_dir, enabled=not getattr(args, "no_cache", False))


if __name__ == "__main__":
    raise SystemExit(main())
