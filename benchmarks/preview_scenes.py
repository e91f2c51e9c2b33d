"""Render the preview pictures of the built-in scenes for ``docs/scenes.md``.

Usage: ``python benchmarks/preview_scenes.py [OUTPUT_DIR]`` (default ``docs/images``). Writes, for
each suite scene, ``scene_<name>.png``: the raster renderer's 4x4 supersampled colour (left),
albedo (middle) and normals (right) at the scene's default resolution, sRGB-encoded with a
simple exposure. The ``street`` scene also gets ``scene_street_frames.png`` (frames 0, 8, 16, 23).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from common import parser, run

from harness import load_plugins

SUITE = ("cornell", "atrium", "courtyard", "street", "furnace")


def encode(image: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """Linear RGB -> 8-bit sRGB after ``exposure`` and Reinhard-free clipping."""
    x = np.clip(image * exposure, 0.0, 1.0)
    x = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    return (x * 255 + 0.5).astype(np.uint8)


def write_png(path: Path, pixels: np.ndarray) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(pixels.shape[1], pixels.shape[0], 3, "uint8"))
    out.write_image(np.ascontiguousarray(pixels))
    out.close()


def main(argv=None) -> int:
    ap = parser(__doc__)
    ap.add_argument("out_dir", nargs="?", type=Path, default=Path("docs/images"), metavar="OUTPUT_DIR")
    out_dir = ap.parse_args(argv).out_dir
    out_dir.mkdir(parents=True, exist_ok=True)
    registry = load_plugins()
    renderer = registry.get("renderer", "raster").factory(supersample=4)
    for name in SUITE:
        scene = registry.get("scene", name).factory()
        frame = renderer.render(scene, 0, channels={"albedo", "normal"})
        color = frame["color"]
        exposure = 0.8 / max(float(np.percentile(color, 97)), 1e-6)
        row = np.concatenate([encode(color, exposure), encode(frame["albedo"]), encode(frame["normal"] * 0.5 + 0.5)],
                             axis=1)
        write_png(out_dir / f"scene_{name}.png", row)
        if scene.frame_count > 1:
            frames = [renderer.render(scene, t)["color"] for t in (0, 8, 16, scene.frame_count - 1)]
            write_png(out_dir / f"scene_{name}_frames.png",
                      np.concatenate([encode(f, exposure) for f in frames], axis=1))
        print(f"{name}: {out_dir / f'scene_{name}.png'}")
    return 0


if __name__ == "__main__":
    run(main)
