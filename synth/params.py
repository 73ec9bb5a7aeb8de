"""Parameter models: one frozen pydantic model per method, defaults = the papers' settings.

The service's OpenAPI schema, the browser form and the CLI's ``--set`` all come from these models;
nothing about a parameter (bounds, default, meaning) is written twice.
"""

from __future__ import annotations

import json
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, ValidationError

from synth.errors import InvalidParameter

__all__ = ["MethodParams", "parse_assignments", "validate_params"]


class MethodParams(BaseModel):
    """Base of every method's parameter model: frozen, and unknown names are errors."""

    model_config = ConfigDict(frozen=True, extra="forbid")


P = TypeVar("P", bound=MethodParams)


def validate_params(model: type[P], values: dict[str, Any] | P | None) -> P:
    """Build ``model`` from ``values``, turning pydantic's report into one :class:`InvalidParameter`.

    The first failing field is named, with pydantic's reason (``Input should be less than or equal
    to 41``), so that a person sees which field to fix before any work starts.
    """
    if isinstance(values, model):
        return values
    try:
        return model.model_validate(values or {})
    except ValidationError as exc:
        err = exc.errors()[0]
        name = ".".join(str(p) for p in err.get("loc", ())) or "params"
        reason = err.get("msg", "invalid value")
        if err.get("type") == "extra_forbidden":
            known = ", ".join(sorted(model.model_fields))
            reason = f"unknown parameter (known: {known})"
        raise InvalidParameter(name, err.get("input"), reason) from None


def parse_assignments(items: list[str], option: str = "--set") -> dict[str, Any]:
    """``['a=1', 'b=ED']`` -> ``{'a': 1, 'b': 'ED'}``: the command lines' ``--set NAME=VALUE``.

    Values parse as JSON when they can (numbers, booleans, lists), else stay strings. The one parser
    of ``texsynth synthesize`` and ``texsynth submit``; a malformed item names ``option``.
    """
    out: dict[str, Any] = {}
    for item in items:
        name, sep, raw = item.partition("=")
        if not sep or not name.strip():
            raise InvalidParameter(option, item, "must look like name=value")
        try:
            out[name.strip()] = json.loads(raw)
        except json.JSONDecodeError:
            out[name.strip()] = raw
    return out
