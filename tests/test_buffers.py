"""Frame validation and the non-finite policy at the harness boundary."""

import numpy as np
import pytest

from harness import ChannelError, Frame, FrameMeta, NonFiniteError
from harness.buffers import check_filter_output
from harness.nonfinite import apply_nonfinite_policy
from harness.testing import make_frame


def test_frame_validates_shape_and_dtype_with_a_precise_message():
    color = np.zeros((4, 5, 3), np.float32)
    with pytest.raises(ChannelError) as err:
        Frame({"color": color, "normal": np.zeros((4, 5, 2), np.float32)}, owner="renderer 'x'")
    msg = str(err.value)
    assert "renderer 'x'" in msg and "'normal'" in msg and "(4, 5, 3)" in msg and "(4, 5, 2)" in msg
    with pytest.raises(
        ChannelError, match=r"'object_id' expected shape \(4, 5\) dtype int32, got shape \(4, 5\) dtype float32"
    ):
        Frame({"color": color, "object_id": np.zeros((4, 5), np.float32)})
    with pytest.raises(ChannelError, match="unknown channel 'colour'"):
        Frame({"color": color, "colour": color})
    with pytest.raises(ChannelError, match="needs a 'color' channel"):
        Frame({"normal": color})


def test_frame_arrays_are_read_only_copies():
    color = np.ones((2, 2, 3), np.float32)
    frame = Frame({"color": color})
    color[0, 0, 0] = 5.0
    assert frame["color"][0, 0, 0] == 1.0
    with pytest.raises(ValueError):
        frame["color"][0, 0, 0] = 2.0


def test_missing_channel_names_scene_and_available_channels():
    frame = Frame({"color": np.zeros((2, 2, 3), np.float32)}, FrameMeta(scene="box"))
    with pytest.raises(KeyError, match="scene 'box' has no channel 'normal'"):
        frame["normal"]


def test_nonfinite_policy_raise_and_repair_count():
    """Colour NaN/Inf are counted; raise names the channels; repair makes them 0."""
    frame = make_frame(4, 4)
    color = frame["color"].copy()
    color[0, 0, 0] = np.nan
    color[1, 1, 2] = np.inf
    depth = frame["depth"].copy()
    depth[2, 2] = np.inf  # background depth is legal
    bad = frame.replace(color=color, depth=depth)
    with pytest.raises(NonFiniteError, match=r"2 non-finite values \(color 2\)"):
        apply_nonfinite_policy(bad, "raise")
    fixed, count = apply_nonfinite_policy(bad, "repair")
    assert count == 2
    assert np.isfinite(fixed["color"]).all() and fixed["color"][1, 1, 2] == 0.0
    assert np.isposinf(fixed["depth"][2, 2])
    same, zero = apply_nonfinite_policy(frame, "raise")
    assert same is frame and zero == 0


def test_filter_output_checks():
    frame = make_frame(3, 4)
    check_filter_output(np.zeros((3, 4, 3), np.float32), frame, owner="filter 'f'")
    with pytest.raises(
        ChannelError, match=r"filter 'f': output expected shape \(3, 4, 3\) dtype float32, got shape \(4, 3, 3\)"
    ):
        check_filter_output(np.zeros((4, 3, 3), np.float32), frame, owner="filter 'f'")
    with pytest.raises(ChannelError, match="dtype float64"):
        check_filter_output(np.zeros((3, 4, 3)), frame, owner="filter 'f'")
    out = np.zeros((3, 4, 3), np.float32)
    out[0, 0, 0] = np.nan
    with pytest.raises(NonFiniteError, match="1 non-finite"):
        check_filter_output(out, frame, owner="filter 'f'")
