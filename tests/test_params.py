"""Declared parameters: types, ranges and choices checked before any work."""

import math

import pytest

from harness import FilterSpec, Param, load_plugins


def _spec(**params):
    return FilterSpec(name="p", version="0", factory=lambda backend="cpu", **kw: None, params=params)


def test_plain_defaults_declare_their_type():
    spec = _spec(n=3, sigma=1.5, flag=True, mode="a", anything=None)
    assert dict(spec.params) == {"n": 3, "sigma": 1.5, "flag": True, "mode": "a", "anything": None}
    assert spec.check_params({"n": 4, "sigma": 2, "flag": False, "mode": "b", "anything": [1]}) == {
        "n": 4, "sigma": 2.0, "flag": False, "mode": "b", "anything": [1]}
    assert isinstance(spec.check_params({"sigma": 2})["sigma"], float)
    for bad in ({"n": 2.5}, {"n": True}, {"sigma": "x"}, {"sigma": math.nan}, {"flag": 1}, {"mode": 3}):
        with pytest.raises(ValueError, match="filter 'p': parameter"):
            spec.check_params(bad)
    with pytest.raises(ValueError, match=r"has no parameter\(s\) \['m'\]"):
        spec.check_params({"m": 1})


def test_ranges_choices_and_lists():
    spec = _spec(
        it=Param(5, min=1, max=10),
        sigma=Param(1.0, min=0, min_exclusive=True),
        mode=Param("a", choices=("a", "b")),
        scales=Param((0.0, 1.0), min=0, max=32),
        path=Param(None, type="str"),
    )
    assert spec.check_params({"it": 10, "sigma": math.inf, "scales": [0, 31.5], "path": "w.npz"})
    assert spec.check_params({"path": None}) == {"path": None}
    cases = {
        "it": (0, "must be int in [1, 10], got 0"),
        "sigma": (0.0, "must be float in (0, inf], got 0.0"),
        "mode": ("c", "must be one of ('a', 'b'), got 'c'"),
        "scales": ([1, 40], "must be list in [0, 32], got [1, 40]"),
        "path": (3, "must be str or null, got 3"),
    }
    for name, (value, message) in cases.items():
        with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")
                           .replace("]", r"\]")):
            spec.check_params({name: value})


def test_a_default_outside_its_declaration_or_a_bad_preset_is_an_error():
    with pytest.raises(ValueError, match="default of parameter 'it'"):
        _spec(it=Param(0, min=1))
    with pytest.raises(ValueError, match="preset 'fast'"):
        FilterSpec(name="p", version="0", factory=None, params={"it": Param(5, min=1)}, presets={"fast": {"it": -1}})


def test_every_builtin_filter_declares_its_parameters():
    """Every default and preset of the built-ins satisfies its declaration (checked when the spec is made)."""
    reg = load_plugins()
    for spec in reg.filters.values():
        assert set(spec.param_specs) == set(spec.params)
        for preset, values in spec.presets.items():
            spec.check_params(values, context=f"preset {preset!r}")
