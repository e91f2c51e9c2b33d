"""The ``emission`` channel: the part of the colour emitted by the first-hit surface."""


from harness.testing import registry


def test_pathtracer_emission_is_the_unbounced_part_of_the_colour():
    reg = registry()
    renderer = reg.renderers["pathtracer"].factory()
    scene = reg.scenes["cornell"].factory()
    frame = renderer.render(scene, 0, spp=4, seed=2, channels={"emission", "object_id"}, resolution=(24, 24))
    emission, color = frame["emission"], frame["color"]
    lit = emission.max(axis=-1) > 0
    assert lit.any() and not lit.all()  # the light is seen, and is not everything
    emitters = {m.emission for m in scene.materials if m.is_emissive}
    assert {tuple(float(v) for v in e) for e in emission[lit]} <= emitters
    assert (color[lit] >= emission[lit] - 1e-5).all()  # reflected light only adds
    assert (emission[frame["object_id"] < 0] == 0).all()


def test_synthetic_scenes_have_no_emitters():
    reg = registry()
    frame = reg.renderers["synthetic"].factory().render(
        reg.scenes["synthetic-edges"].factory(), 0, spp=1, seed=0, channels={"emission"}, resolution=(8, 6)
    )
    assert frame["emission"].shape == (6, 8, 3) and not frame["emission"].any()
