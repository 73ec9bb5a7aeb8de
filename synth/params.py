"""Parameter models: one frozen pydantic model per method, defaults = the papers' settings.

The service's OpenAPI schema, the browser form and the CLI's ``--set`` all come from these models;
nothing about a parameter (bounds, default, meaning) is written twice. A field's ``description`` is one
plain sentence (the paper's symbol in brackets); :func:`ui` adds what a form needs beyond JSON Schema:
``x-basic`` (shown before "Advanced"), ``x-unit``, ``x-odd`` and ``x-details`` (the longer explanation).
"""

from __future__ import annotations

import json
import re
from typing import Any, TypeVar

from pydantic import BaseModel, ConfigDict, ValidationError

from texsynth.synth.errors import InvalidParameter, InvalidParameters

__all__ = ["BOUNDS", "MethodParams", "parse_assignments", "ui", "validate_params"]

#: The JSON Schema bounds a form shows and checks.
BOUNDS: tuple[str, ...] = ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum")


def ui(
    *, basic: bool = False, unit: str | None = None, odd: bool = False, details: str | None = None
) -> dict[str, Any]:
    """A field's form hints, for ``Field(json_schema_extra=ui(...))``.

    Parameters
    ----------
    basic : bool
        One of the few parameters a user changes (sizes, neighbourhood or patch size, periodic, the
        main weight): shown first; the rest go under "Advanced" (``x-basic``).
    unit : str, optional
        The value's unit: ``'px'``, ``'voxels'``, ``'degrees'``, ``'periods'`` (``x-unit``).
    odd : bool
        The value must be odd (``x-odd``; the model checks it too).
    details : str, optional
        A longer explanation than the one-sentence description (``x-details``).
    """
    extra: dict[str, Any] = {}
    if basic:
        extra["x-basic"] = True
    if unit:
        extra["x-unit"] = unit
    if odd:
        extra["x-odd"] = True
    if details:
        extra["x-details"] = details
    return extra


def _form_schema(schema: dict[str, Any]) -> None:
    """A model's JSON schema as a form reads it: the bounds of an optional field
    (``anyOf: [{..., minimum}, {type: null}]``) also on the property itself, and ``nullable`` said."""
    for prop in schema.get("properties", {}).values():
        branches = prop.get("anyOf")
        if not branches:
            continue
        values = [b for b in branches if b.get("type") != "null"]
        if len(values) == 1 and len(values) < len(branches):
            prop["nullable"] = True
            for key in BOUNDS:
                if key in values[0] and key not in prop:
                    prop[key] = values[0][key]


class MethodParams(BaseModel):
    """Base of every method's parameter model: frozen, and unknown names are errors."""

    model_config = ConfigDict(frozen=True, extra="forbid", json_schema_extra=_form_schema)


P = TypeVar("P", bound=MethodParams)


def validate_params(model: type[P], values: dict[str, Any] | P | None) -> P:
    """Build ``model`` from ``values``, turning pydantic's report into :class:`InvalidParameters`.

    Each failing field is named once, with pydantic's reason (``Input should be less than or equal
    to 41``), so that a person sees which fields to fix before any work starts. A check of the whole
    model (``neighbourhood_size must be odd``) is charged to the first field its message names, with
    that field's value, never the whole dictionary.
    """
    if isinstance(values, model):
        return values
    try:
        return model.model_validate(values or {})
    except ValidationError as exc:
        given = values if isinstance(values, dict) else {}
        problems: dict[str, InvalidParameter] = {}
        for err in exc.errors():
            loc = [str(p) for p in err.get("loc", ())]
            reason = str(err.get("msg", "invalid value")).removeprefix("Value error, ")
            value = err.get("input")
            if err.get("type") == "extra_forbidden":
                reason = f"unknown parameter (known: {', '.join(sorted(model.model_fields))})"
            if not loc:  # a model validator: charge the field its message names
                named = _named_field(model, reason)
                loc = [named] if named else []
                value = given.get(named, getattr(model.model_fields.get(named or ""), "default", None))
            name = ".".join(loc[:1]) or "params"
            problems.setdefault(name, InvalidParameter(name, value, reason.splitlines()[0]))
        raise InvalidParameters(list(problems.values())) from None


def _named_field(model: type[BaseModel], message: str) -> str | None:
    """The first field of ``model`` that ``message`` names as a whole word."""
    words = re.findall(r"[A-Za-z_][A-Za-z0-9_]*", message)
    return next((w for w in words if w in model.model_fields), None)


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
