"""The run manifest lists, per scene, what the scene's plugin renders approximately."""

import json
import textwrap

import pandas as pd

from tests.test_run import bench


def test_manifest_lists_the_approximations_of_a_mitsuba_scene(tmp_path):
    """A Mitsuba scene with a directional light (approximated by a small disc) and an exact spot light,
    run through ``denoise-bench run``: its manifest entry names the directional approximation only."""
    folder = tmp_path / "lamp"
    folder.mkdir()
    (folder / "scene.xml").write_text(textwrap.dedent("""\
        <scene version="3.0.0">
          <sensor type="perspective"><float name="fov" value="45"/>
            <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/></film>
          </sensor>
          <shape type="rectangle"><transform name="to_world"><scale value="2"/></transform>
            <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf></shape>
          <emitter type="directional"><vector name="direction" x="0.2" y="-0.3" z="-1"/>
            <rgb name="irradiance" value="2, 2, 2"/></emitter>
          <emitter type="spot"><transform name="to_world"><lookat origin="0, 0, 2" target="0, 0, 0" up="0, 1, 0"/>
            </transform><rgb name="intensity" value="3, 3, 3"/></emitter>
        </scene>"""))
    out = tmp_path / "out"
    bench(["run", "--scene-dir", folder, "--filters", "passthrough", "--frames", "1", "--spp", "1", "--seeds", "0",
           "--reference-spp", "4", "--reference-target", "0", "--timing-at", "none", "--repeats", "1",
           "--executor", "inline", "--quiet", "--cache-dir", tmp_path / "cache", "--out", out])
    assert set(pd.read_parquet(out / "results.parquet").status) == {"ok"}
    manifest = json.loads((out / "manifest.json").read_text())
    notes = manifest["scene_approximations"]
    assert list(notes) == ["lamp"], notes
    assert any("directional light approximated" in n for n in notes["lamp"]), notes
    assert not any("spot" in n for n in notes["lamp"]), notes
