"""The engine's entry point: which inputs a method takes (one rule for API, CLI and service), sizes."""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.api import METHODS as REGISTRY
from texsynth.synth.api import PLANES, MethodSpec, Result, check_inputs, synthesize
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.params import MethodParams


class _NoParams(MethodParams):
    pass


def _record(exemplar, *, size, params, seed, progress, constraint=None, exemplars=None) -> Result:
    """A 'method' that returns what it was given, so the tests see the API's plumbing."""
    volume = np.zeros(size, np.float32)
    for plane, axis in zip(PLANES, (0, 1, 2), strict=True):
        volume += float(exemplars[plane].mean()) * (axis + 1) / 6  # distinguishes the planes
    return Result(
        "probe-solid", volume, {}, seed, {}, stats={"shapes": {p: e.shape for p, e in exemplars.items()}}
    )


SOLID = MethodSpec("probe-solid", "probe", _NoParams, _record, output_ndim=3, plane_exemplars=True)
FLAT = MethodSpec("probe-flat", "probe", _NoParams, _record)
SHAPED = MethodSpec("probe-shaped", "probe", _NoParams, _record, constraint="required")


@pytest.fixture
def solid():
    REGISTRY[SOLID.name] = SOLID
    yield SOLID
    REGISTRY.pop(SOLID.name, None)


def test_methods_declare_their_inputs():
    assert FLAT.inputs == {"exemplar": "required"}
    assert SHAPED.inputs == {"exemplar": "required", "constraint": "required"}
    assert SOLID.inputs == {
        "exemplar": "alternative",
        "exemplar_xy": "alternative",
        "exemplar_xz": "alternative",
        "exemplar_yz": "alternative",
    }


@pytest.mark.parametrize(
    ("spec", "roles", "field", "message"),
    [
        (FLAT, set(), "exemplar", "missing: method 'probe-flat' needs an exemplar image$"),
        (FLAT, {"exemplar", "constraint"}, "constraint", "takes no constraint image; leave it out"),
        (FLAT, {"exemplar", "exemplar_xy"}, "exemplar_xy", "takes one exemplar, not one per plane"),
        (FLAT, {"exemplar", "mask"}, "mask", r"not an input of method 'probe-flat' \(inputs: exemplar\)"),
        (SHAPED, {"exemplar"}, "constraint", "needs a constraint image"),
        (
            SOLID,
            set(),
            "exemplar",
            r"needs an exemplar image \(or exemplar_xy, exemplar_xz and exemplar_yz\)",
        ),
        (
            SOLID,
            {"exemplar_xy", "exemplar_yz"},
            "exemplar_xz",
            "missing: per-plane exemplars come as all three",
        ),
        (
            SOLID,
            {"exemplar", "exemplar_xy", "exemplar_xz", "exemplar_yz"},
            "exemplar",
            "one exemplar or one per",
        ),
    ],
)
def test_check_inputs_names_the_input(spec, roles, field, message):
    with pytest.raises(InvalidInput, match=message) as info:
        check_inputs(spec, roles)
    assert info.value.source == field


@pytest.mark.parametrize("roles", [{"exemplar"}, {"exemplar_xy", "exemplar_xz", "exemplar_yz"}])
def test_solid_inputs_accepted(roles):
    check_inputs(SOLID, roles)


def test_per_plane_exemplars_reach_the_method_each_in_its_plane(solid):
    planes = {
        "xy": np.full((16, 20), 0.6, np.float32),
        "xz": np.zeros((12, 20), np.float32),
        "yz": np.zeros((12, 16), np.float32),
    }
    result = synthesize("probe-solid", exemplars=planes, size=(8, 9, 10))
    assert result.image.shape == (8, 9, 10)
    assert result.stats["shapes"] == {"xy": (16, 20), "xz": (12, 20), "yz": (12, 16)}
    np.testing.assert_allclose(result.image, 0.6 / 6, rtol=1e-6)  # only the xy exemplar is bright


def test_isotropic_exemplar_serves_all_three_planes_and_default_size_is_its_scale(solid):
    result = synthesize("probe-solid", np.full((24, 32), 0.5, np.float32))
    assert result.image.shape == (24, 24, 32)
    assert result.stats["shapes"] == {p: (24, 32) for p in PLANES}


def test_solid_methods_take_grey_exemplars(solid):
    rgb = np.zeros((16, 16, 3), np.float32)
    with pytest.raises(InvalidInput, match="exemplar: solid methods take grey exemplars"):
        synthesize("probe-solid", rgb, size=(8, 8, 8))


@pytest.mark.parametrize(
    ("size", "message"),
    [
        ((16, 16), r"needs 3 values: this method makes a volume \(D, H, W\)"),
        ((4, 16, 16), r"each side must lie in \[8, 8192\] pixels"),
        ((16, 16.5, 16), "must be a whole number of pixels"),
        ((1024, 1024, 1024), "an output of 1073741824 voxels is more than the limit of 134217728"),
    ],
)
def test_bad_volume_sizes_fail_before_any_work(solid, size, message):
    with pytest.raises(InvalidParameter, match=message):
        synthesize("probe-solid", np.zeros((16, 16), np.float32), size=size)


def test_output_limit_follows_the_environment(solid, monkeypatch):
    monkeypatch.setenv("TEXSYNTH_MAX_OUTPUT", "1000")
    with pytest.raises(InvalidParameter, match="more than the limit of 1000"):
        synthesize("probe-solid", np.zeros((16, 16), np.float32), size=(10, 10, 11))
