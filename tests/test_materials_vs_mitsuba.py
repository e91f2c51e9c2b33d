"""Mitsuba materials against Mitsuba 3 itself: small scenes rendered by both, compared by region means.

Each case is a Mitsuba 3 XML scene written here: a tessellated sphere (the same OBJ triangles and
normals for both renderers) on a floor, with one BSDF variant, lit either by a uniform
environment or by a one-sided area light above (floor and a back wall then close the view). The
harness loads the file with its Mitsuba plugin and renders it with the path tracer; Mitsuba 3
(``scalar_rgb``, ``path`` integrator, the same ``max_depth`` and Russian-roulette depth) renders
the same file with several seeds.

The statistical test, per region of a 4x4 grid: ``z = (H - M) / sqrt(var_H + var_M)``, where
``H`` is the harness's region mean (pixel areas integrated on a 4x4 grid of pixel centres, as
Mitsuba samples pixel areas) with ``var_H`` the sum of its pixels' variance-of-the-mean channel
over the region's pixel count squared, and ``M`` the mean of Mitsuba's renders over its seeds
with ``var_M`` from the per-pixel spread between seeds, summed the same way (pooled over the
region's pixels, so the noise estimate itself is precise), plus ``(0.004 M)^2``: the 4x4 grid of
centres integrates a pixel that a silhouette crosses only to a sixteenth of its area, which moves
a region mean by up to about 0.4% (measured on these scenes), and the noiseless background differs
by float32 rounding only. A case passes when every region (and
colour channel) has ``|z| <= Z_MAX``. With 16 x 3 comparisons per case and 30 cases, ``Z_MAX =
4.5`` gives a false failure about once in 200 runs of the whole file; a missing Fresnel factor
shifts region means by 5-50%, i.e. more than ten times that margin (``docs/pathtracer.md``,
mutation checks).

Needs the optional ``validate`` extra (``pip install -e ".[validate]"``: Mitsuba 3); skipped
with a message without it. Only the ``scalar_rgb`` variant is used.
"""

from __future__ import annotations

import multiprocessing
import textwrap
import warnings
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="Mitsuba 3 is not installed (pip install -e '.[validate]')")

from plugins.renderers.pathtracer import PathTracer  # noqa: E402
from plugins.scenes.mitsuba import MitsubaWarning, load  # noqa: E402

pytestmark = pytest.mark.slow

Z_MAX = 4.5
MARGIN = 4e-3  # relative: the harness integrates pixel areas on a 4x4 grid of centres (exact to ~0.4% at edges)
SIZE = 32  # Mitsuba's film; the harness renders SUPER x SUPER pixel centres per pixel
SUPER = 4
GRID = 4
MAX_DEPTH = 6
SEEDS = 8
MITSUBA_SPP = 64
HARNESS_SPP = 36

# a smooth height field (raw float EXR) for bump maps: 4 x 3 periods of a product of sines in uv
HEIGHT = """<texture type="bitmap"><string name="filename" value="height.exr"/><boolean name="raw" value="true"/>
        </texture>"""
BSDFS = {
    "diffuse-textured": """<bsdf type="diffuse"><texture type="bitmap" name="reflectance">
        <string name="filename" value="checker.png"/>
        <transform name="to_uv"><scale x="3" y="2"/><translate x="0.25"/></transform></texture></bsdf>""",
    "plastic": """<bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.6, 0.2, 0.1"/>
        <float name="int_ior" value="1.5"/></bsdf>""",
    "plastic-nonlinear": """<bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.9, 0.5, 0.2"/>
        <boolean name="nonlinear" value="true"/></bsdf>""",
    "roughplastic-ggx": """<bsdf type="roughplastic"><string name="distribution" value="ggx"/>
        <float name="alpha" value="0.1"/><float name="int_ior" value="1.5"/><boolean name="nonlinear" value="true"/>
        <texture type="bitmap" name="diffuse_reflectance"><string name="filename" value="checker.png"/></texture>
        </bsdf>""",
    "roughplastic-beckmann": """<bsdf type="roughplastic"><float name="alpha" value="0.3"/>
        <rgb name="diffuse_reflectance" value="0.2, 0.5, 0.7"/></bsdf>""",
    "conductor-au": """<bsdf type="conductor"><string name="material" value="Au"/></bsdf>""",
    "roughconductor-ggx": """<bsdf type="roughconductor"><string name="distribution" value="ggx"/>
        <float name="alpha" value="0.2"/><rgb name="eta" value="1.65746, 0.880369, 0.521229"/>
        <rgb name="k" value="9.22387, 6.26952, 4.837"/><rgb name="specular_reflectance" value="0.75, 0.6, 0.5"/>
        </bsdf>""",
    "roughconductor-aniso": """<bsdf type="roughconductor"><string name="material" value="Cu"/>
        <float name="alpha_u" value="0.05"/><float name="alpha_v" value="0.3"/></bsdf>""",
    "dielectric": """<bsdf type="dielectric"><float name="int_ior" value="1.5"/></bsdf>""",
    "roughdielectric": """<bsdf type="roughdielectric"><string name="distribution" value="ggx"/>
        <float name="alpha" value="0.2"/><float name="int_ior" value="1.5"/></bsdf>""",
    "thindielectric": """<bsdf type="thindielectric"><float name="int_ior" value="1.5"/></bsdf>""",
    "onesided-diffuse": """<bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.8, 0.8"/></bsdf>""",
    "twosided-two": """<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.2, 0.2"/></bsdf>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.2, 0.8"/></bsdf></bsdf>""",
    "mask": """<bsdf type="mask"><texture type="bitmap" name="opacity"><string name="filename" value="checker.png"/>
        </texture><bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.6, 0.2"/></bsdf>
        </bsdf></bsdf>""",
    "blendbsdf": """<bsdf type="blendbsdf"><float name="weight" value="0.3"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.1, 0.6, 0.2"/></bsdf>
        <bsdf type="roughconductor"><string name="material" value="Ag"/><float name="alpha" value="0.15"/></bsdf>
        </bsdf>""",
    "bumpmap": f"""<bsdf type="bumpmap">{HEIGHT}<float name="scale" value="0.1"/>
        <bsdf type="roughplastic"><float name="alpha" value="0.2"/>
        <rgb name="diffuse_reflectance" value="0.6, 0.4, 0.2"/></bsdf></bsdf>""",
    "twosided-bumpmap": f"""<bsdf type="twosided"><bsdf type="bumpmap">{HEIGHT}<float name="scale" value="0.1"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.5, 0.3"/></bsdf></bsdf></bsdf>""",
    "bumpmap-twosided": f"""<bsdf type="bumpmap">{HEIGHT}<float name="scale" value="0.1"/><bsdf type="twosided">
        <bsdf type="diffuse"><rgb name="reflectance" value="0.3, 0.5, 0.8"/></bsdf></bsdf></bsdf>""",
}
# the sphere is cut open (a hemisphere bowl) for the cases whose back side must show
OPEN = {"onesided-diffuse", "twosided-two", "twosided-bumpmap", "bumpmap-twosided"}

CAMERA = """<sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0.4, 1.6, 4.2" target="0, 0.6, 0" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    <film type="hdrfilm"><integer name="width" value="{size}"/><integer name="height" value="{size}"/>
    <rfilter type="box"/></film></sensor>"""
FLOOR = """<shape type="rectangle"><transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/>
    </transform><bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf></shape>"""
WALL = """<shape type="rectangle"><transform name="to_world"><scale value="3"/><translate y="1" z="-2"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf></shape>"""
LIGHTS = {
    "env": """<emitter type="constant"><rgb name="radiance" value="1.0, 0.9, 0.8"/></emitter>""",
    "area": """<shape type="rectangle"><transform name="to_world"><scale value="0.6"/><rotate x="1" angle="90"/>
        <translate x="0.5" y="2.6" z="0.4"/></transform>
        <emitter type="area"><rgb name="radiance" value="12, 11, 10"/></emitter></shape>""" + WALL,
}


def sphere_obj(path, *, rings=24, segments=48, open_top=False) -> None:
    """A UV sphere of radius 0.6 at (0, 0.6, 0) as OBJ with positions, uvs and normals."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    lines = []
    for t in theta:
        for p in phi:
            n = (np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p))
            lines.append(f"v {0.6 * n[0]:.7f} {0.6 + 0.6 * n[1]:.7f} {0.6 * n[2]:.7f}")
            lines.append("vn {:.7f} {:.7f} {:.7f}".format(*n))
    for t in theta:
        for p in phi:
            lines.append(f"vt {p / (2 * np.pi):.7f} {1.0 - t / np.pi:.7f}")
    first = rings // 2 if open_top else 0
    for i in range(first, rings):
        for j in range(segments):
            a = i * (segments + 1) + j + 1
            b = a + segments + 1
            for tri in ((a, a + 1, b + 1), (a, b + 1, b)):
                lines.append("f " + " ".join(f"{k}/{k}/{k}" for k in tri))
    path.write_text("\n".join(lines) + "\n")


def checker_png(path) -> None:
    """An 8-bit sRGB checkerboard (8 x 8 squares) with a soft gradient, for textures and opacity."""
    import OpenImageIO as oiio

    y, x = np.mgrid[0:64, 0:64]
    check = ((x // 8 + y // 8) % 2).astype(float)
    img = np.stack([0.1 + 0.8 * check, 0.2 + 0.6 * x / 63, 0.9 - 0.7 * check], -1)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(64, 64, 3, "uint8"))
    out.write_image((img * 255 + 0.5).astype(np.uint8))
    out.close()


def height_exr(path) -> None:
    """A grey float height map, ``0.5 + 0.5 sin(8 pi x) sin(6 pi y)`` on 64 x 64 texels."""
    import OpenImageIO as oiio

    y, x = np.mgrid[0:64, 0:64] / 64.0
    h = 0.5 + 0.5 * np.sin(8 * np.pi * x) * np.sin(6 * np.pi * y)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(64, 64, 3, "float"))
    out.write_image(np.ascontiguousarray(np.repeat(h[..., None], 3, -1).astype(np.float32)))
    out.close()


def write_case(folder, bsdf: str, light: str, *, open_top=False):
    sphere_obj(folder / "sphere.obj", open_top=open_top)
    checker_png(folder / "checker.png")
    height_exr(folder / "height.exr")
    xml = f"""<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="{MAX_DEPTH}"/><integer name="rr_depth" value="5"/>
    </integrator>
    {CAMERA.format(spp=MITSUBA_SPP, size=SIZE)}
    {FLOOR}
    <shape type="obj"><string name="filename" value="sphere.obj"/>{bsdf}</shape>
    {LIGHTS[light]}
    </scene>"""
    (folder / "scene.xml").write_text(textwrap.dedent(xml))
    return folder / "scene.xml"


def _mitsuba_images(xml_path: str) -> np.ndarray:
    mi.set_variant("scalar_rgb")
    scene = mi.load_file(xml_path)
    return np.stack([np.asarray(mi.render(scene, seed=seed, spp=MITSUBA_SPP), np.float64)[..., :3]
                     for seed in range(SEEDS)])


@pytest.fixture(scope="module", autouse=True)
def mitsuba_process():
    """One fresh process renders Mitsuba 3's images: this test process may already hold another
    variant's state (the ``mitsuba`` renderer's ``llvm_ad_rgb``), which ``scalar_rgb`` need not meet."""
    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        POOL[:] = [pool]
        yield pool
        POOL.clear()


#: the module's Mitsuba process (:func:`mitsuba_process`)
POOL: list = []


def render_mitsuba(xml_path) -> np.ndarray:
    """(SEEDS, H, W, 3) float64 renders of Mitsuba 3 ``scalar_rgb``, made in the module's own process."""
    return POOL[0].submit(_mitsuba_images, str(xml_path)).result()


def render_harness(xml_path):
    """(mean, variance of the mean) per film pixel, (H, W, 3) float64, from SUPER^2 centres per pixel."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        scene = load(xml_path.parent)
    renderer = PathTracer(max_depth=MAX_DEPTH, rr_depth=5)
    n = SIZE * SUPER
    frame = renderer.render(scene, 0, spp=HARNESS_SPP, seed=1, channels={"variance"}, resolution=(n, n))
    colour = frame["color"].astype(np.float64).reshape(SIZE, SUPER, SIZE, SUPER, 3)
    var = frame["variance"].astype(np.float64).reshape(SIZE, SUPER, SIZE, SUPER, 3)
    return colour.mean(axis=(1, 3)), var.sum(axis=(1, 3)) / SUPER**4


def region_stats(mean: np.ndarray, var: np.ndarray):
    """Region means and their variances on a GRID x GRID grid."""
    r = SIZE // GRID
    m = mean.reshape(GRID, r, GRID, r, 3).mean(axis=(1, 3))
    v = var.reshape(GRID, r, GRID, r, 3).sum(axis=(1, 3)) / (r * r) ** 2
    return m, v


def compare(xml_path):
    """(z scores, harness/Mitsuba ratios) per region and channel."""
    mits = render_mitsuba(xml_path)
    m_mean = mits.mean(axis=0)
    m_var = mits.var(axis=0, ddof=1) / SEEDS
    h_mean, h_var = render_harness(xml_path)
    hm, hv = region_stats(h_mean, h_var)
    mm, mv = region_stats(m_mean, m_var)
    margin = (MARGIN * mm) ** 2
    z = (hm - mm) / np.sqrt(np.maximum(hv + mv + margin, 1e-30))
    ratio = (hm + 1e-6) / (mm + 1e-6)
    return z, ratio


CASES = [(name, light) for name in BSDFS for light in LIGHTS]


@pytest.mark.parametrize("name,light", CASES, ids=[f"{n}-{lt}" for n, lt in CASES])
def test_material_agrees_with_mitsuba(tmp_path, name, light):
    xml = write_case(tmp_path, BSDFS[name], light, open_top=name in OPEN)
    z, ratio = compare(xml)
    worst = np.unravel_index(np.argmax(np.abs(z)), z.shape)
    assert np.abs(z).max() <= Z_MAX, (
        f"{name} under {light}: region {worst[:2]} channel {worst[2]} differs by z = {z[worst]:.1f} "
        f"(harness / Mitsuba = {ratio[worst]:.4f}); region ratios median {np.median(ratio):.4f}, "
        f"range {ratio.min():.4f}-{ratio.max():.4f}")


def test_envmap_rotation_and_scale_agree_with_mitsuba(tmp_path):
    """An equirectangular map with a tilted ``to_world`` and a ``scale`` lighting a diffuse sphere."""
    import OpenImageIO as oiio

    h, w = 32, 64
    v, u = np.mgrid[0:h, 0:w]
    img = np.stack([0.2 + 2.0 * np.exp(-((u - 20) ** 2 + (v - 10) ** 2) / 20.0), 0.3 + 0.01 * u, 0.4 + 0.02 * v], -1)
    out = oiio.ImageOutput.create(str(tmp_path / "sky.exr"))
    out.open(str(tmp_path / "sky.exr"), oiio.ImageSpec(w, h, 3, "float"))
    out.write_image(img.astype(np.float32))
    out.close()
    env = """<emitter type="envmap"><string name="filename" value="sky.exr"/><float name="scale" value="1.7"/>
        <transform name="to_world"><rotate y="1" angle="70"/><rotate x="1" angle="25"/></transform></emitter>"""
    LIGHTS["envmap"] = env
    try:
        xml = write_case(tmp_path, BSDFS["roughplastic-beckmann"], "envmap")
    finally:
        del LIGHTS["envmap"]
    z, ratio = compare(xml)
    assert np.abs(z).max() <= Z_MAX, (
        f"envmap: max |z| = {np.abs(z).max():.1f}, ratios {ratio.min():.4f}-{ratio.max():.4f}")


@pytest.mark.parametrize("light", ["point", "directional", "spot"])
def test_delta_lights_agree_with_mitsuba(tmp_path, light):
    """Mitsuba's point and directional lights (the harness's small sphere and small disc of the
    same intensity and irradiance) and its spot light (a delta light of the path tracer, with the
    falloff's edge in view) lighting the rough plastic sphere on the floor, the wall behind."""
    LIGHTS[light] = {
        "point": """<emitter type="point"><point name="position" x="0.8" y="2.2" z="1.0"/>
            <rgb name="intensity" value="6, 5, 4"/></emitter>""",
        "spot": """<emitter type="spot"><rgb name="intensity" value="9, 8, 6"/>
            <float name="cutoff_angle" value="28"/><float name="beam_width" value="14"/>
            <transform name="to_world"><lookat origin="0.9, 2.6, 1.4" target="-0.2, 0.3, -0.3" up="0, 1, 0"/>
            </transform></emitter>""",
        "directional": """<emitter type="directional"><vector name="direction" x="-0.4" y="-1" z="-0.5"/>
            <rgb name="irradiance" value="3, 2.5, 2"/></emitter>""",
    }[light] + WALL
    try:
        xml = write_case(tmp_path, BSDFS["roughplastic-beckmann"], light)
    finally:
        del LIGHTS[light]
    z, ratio = compare(xml)
    assert np.abs(z).max() <= Z_MAX, (
        f"{light}: max |z| = {np.abs(z).max():.1f}, ratios {ratio.min():.4f}-{ratio.max():.4f}, "
        f"median {np.median(ratio):.4f}")
