"""harness.exr: OpenEXR channels in and out, exactly, and the capture writer's layout."""

from __future__ import annotations

import json

import numpy as np
import pytest

from harness import (
    CHANNELS,
    ExrError,
    Frame,
    FrameMeta,
    read_channels,
    read_size,
    write_capture,
    write_channels,
    write_exr,
)
from harness.exr import COMPONENTS, EXACT_INT, layer_channels


def test_every_channel_has_components_of_its_size():
    assert set(COMPONENTS) == set(CHANNELS)
    for name, (count, _, _) in CHANNELS.items():
        assert len(COMPONENTS[name]) == count


def test_float32_round_trip_is_exact_nan_and_inf_included(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.standard_normal((5, 7)).astype(np.float32) * 1e6
    a[0, 0], a[0, 1], a[0, 2] = np.nan, np.inf, -np.inf
    a[1, 0] = np.float32(1e-42)  # subnormal
    b = rng.random((5, 7)).astype(np.float32)
    path = write_channels(tmp_path / "x.exr", {"layer.R": a, "other.Z": b})
    channels, size = read_channels(path)
    assert size == (7, 5) and read_size(path) == (7, 5)
    assert sorted(channels) == ["layer.R", "other.Z"]
    assert channels["layer.R"].dtype == np.float32
    assert channels["layer.R"].tobytes() == a.tobytes()
    assert channels["other.Z"].tobytes() == b.tobytes()


def test_half_is_widened_to_float32_exactly(tmp_path):
    values = np.array([[0.5, 1.0 / 3.0, 65504.0, 1e-5]], np.float32)
    channels, _ = read_channels(write_channels(tmp_path / "h.exr", {"Y": values}, half=True))
    assert channels["Y"].dtype == np.float32
    np.testing.assert_array_equal(channels["Y"], values.astype(np.float16).astype(np.float32))


def test_uint_channels_are_read_as_their_integer_values(tmp_path):
    import OpenImageIO as oiio

    path = tmp_path / "u.exr"
    spec = oiio.ImageSpec(3, 2, 2, "float")
    spec.channelnames = ("id.Y", "R")
    spec.channelformats = (oiio.TypeDesc("uint"), oiio.TypeDesc("float"))
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    ids = np.array([[0, 1, 7], [70000, 3, 2]], np.uint32)
    # OpenImageIO normalises integer types on conversion: write the ids through a uint buffer
    out.write_image(np.stack([ids, np.zeros_like(ids)], axis=-1).astype(np.uint32))
    out.close()
    channels, _ = read_channels(path)
    assert channels["id.Y"].dtype == np.uint32
    np.testing.assert_array_equal(channels["id.Y"], ids)


def test_write_exr_names_rgb(tmp_path):
    image = np.arange(2 * 3 * 3, dtype=np.float32).reshape(2, 3, 3)
    channels, _ = read_channels(write_exr(tmp_path / "out.exr", image))
    assert sorted(channels) == ["B", "G", "R"]
    np.testing.assert_array_equal(np.stack([channels[c] for c in "RGB"], axis=-1), image)


@pytest.mark.parametrize(
    ("content", "match"),
    [(None, "cannot open"), (b"not an image at all", "cannot open")],
    ids=["missing", "garbage"],
)
def test_unreadable_files_raise_one_line_naming_the_file(tmp_path, content, match):
    path = tmp_path / "bad.exr"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(ExrError, match=match) as info:
        read_channels(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_truncated_file_raises(tmp_path):
    rng = np.random.default_rng(1)
    path = write_channels(tmp_path / "t.exr", {"R": rng.random((64, 64)).astype(np.float32)})
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ExrError) as info:
        read_channels(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_data_window_other_than_display_window_is_refused(tmp_path):
    import OpenImageIO as oiio

    path = tmp_path / "crop.exr"
    spec = oiio.ImageSpec(4, 4, 1, "float")
    spec.full_width, spec.full_height = 8, 8
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(np.zeros((4, 4, 1), np.float32))
    out.close()
    with pytest.raises(ExrError, match="data window"):
        read_channels(path)


def test_write_channels_refuses_mixed_sizes(tmp_path):
    with pytest.raises(ExrError, match="shape"):
        write_channels(tmp_path / "m.exr", {"A": np.zeros((2, 2)), "B": np.zeros((2, 3))})


def test_integer_channels_beyond_float32_exactness_are_refused():
    ok = layer_channels("object_id", "object_id", np.array([[-1, EXACT_INT]], np.int32))
    assert ok["object_id.Y"].dtype == np.float32
    with pytest.raises(ExrError, match="exactly"):
        layer_channels("object_id", "object_id", np.array([[EXACT_INT + 1]], np.int32))


def test_write_capture_layout_and_sidecar(tmp_path):
    h, w = 3, 4
    frames = [
        Frame({"color": np.full((h, w, 3), t, np.float32), "depth": np.full((h, w), np.inf, np.float32)},
              FrameMeta(index=t, scene="demo", seed=5))
        for t in range(2)
    ]
    refs = [np.ones((h, w, 3), np.float32)] * 2
    sidecar = write_capture(tmp_path / "cap", frames, refs, spp=1, reference_spp=64, tags=["static"])
    data = json.loads(sidecar.read_text())
    assert data["name"] == "demo" and data["frames"] == 2 and data["preset"] == "harness"
    assert data["channels"] == {"color": "color", "depth": "depth"}
    assert data["reference"] == {"file": "reference/{frame:04d}.exr", "layer": "", "spp": 64}
    assert [m["seed"] for m in data["frame"]] == [5, 5]
    channels, _ = read_channels(tmp_path / "cap" / "frames" / "0001.exr")
    assert sorted(channels) == ["color.B", "color.G", "color.R", "depth.Z"]
    assert np.isposinf(channels["depth.Z"]).all()
    assert sorted(read_channels(tmp_path / "cap" / "reference" / "0000.exr")[0]) == ["B", "G", "R"]


def test_write_capture_refuses_inconsistent_frames(tmp_path):
    a = Frame({"color": np.zeros((2, 2, 3), np.float32)})
    b = Frame({"color": np.zeros((2, 3, 3), np.float32)})
    with pytest.raises(ValueError, match="frame 1"):
        write_capture(tmp_path / "c", [a, b])
    with pytest.raises(ValueError, match="references"):
        write_capture(tmp_path / "c", [a], [None, None])
