"""Every method, its defaults and every value of every option with a set of choices, on a small laminar
exemplar, a flat one and a tiny one: a run either finishes with a finite output of the asked shape, or
stops with the engine's named error (``InvalidInput`` / ``InvalidParameter``), never another exception. (A
sweep like this found the crashes of session 17: a structured start on a tiny or a flat exemplar, strand
hints on an output shorter than their spacing.)"""

from __future__ import annotations

import numpy as np
import pytest

from texsynth.synth.api import available_methods, synthesize
from texsynth.synth.errors import InvalidInput, InvalidParameter
from texsynth.synth.io.laminar import onion_volume

METHODS = sorted(name for name in available_methods() if not name.startswith("test-"))
CONSTRAINT = (np.indices((32, 32)).sum(0) % 16 < 8).astype(np.float32)


def _choices(schema: dict) -> list[tuple[str, object]]:
    """(field, value) for every enumerated value and both booleans of the parameters' JSON schema."""
    out = []
    for field, info in schema["properties"].items():
        values = list(info.get("enum", [])) + [v for a in info.get("anyOf", []) for v in a.get("enum", [])]
        if info.get("type") == "boolean":
            values = [True, False]
        out += [(field, v) for v in values]
    return out


def _run(name: str, exemplar: np.ndarray, params: dict) -> None:
    spec = available_methods()[name]
    size = (12, 12, 12) if spec.output_ndim == 3 else (32, 32)
    extra = {"constraint": CONSTRAINT} if spec.constraint == "required" else {}
    try:
        result = synthesize(name, exemplar, size=size, params=params, seed=1, **extra)
    except (InvalidInput, InvalidParameter):
        return
    assert result.image.shape[: len(size)] in (size, size[::-1])
    assert np.isfinite(result.image).all()


#: A laminar exemplar, a flat one and one under the 12 px a structured start needs.
EXEMPLARS = {
    "laminar": onion_volume((48, 48, 48), seed=1)[24].astype(np.float32),
    "flat": np.full((32, 32), 0.4, dtype=np.float32),
    "tiny": np.random.default_rng(0).random((11, 11)).astype(np.float32),
}


@pytest.mark.parametrize("kind", sorted(EXEMPLARS))
@pytest.mark.parametrize("name", METHODS)
def test_every_choice_finishes_or_names_its_problem(name: str, kind: str) -> None:
    choices = _choices(available_methods()[name].params_model.model_json_schema())
    assert choices, f"{name} has no enumerated option"
    for field, value in [(None, None), *choices]:
        _run(name, EXEMPLARS[kind], {} if field is None else {field: value})
