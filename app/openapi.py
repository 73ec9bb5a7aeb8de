"""The OpenAPI document, made for client generators (``openapi-python-client``, OpenAPI Generator).

FastAPI's own document describes the routes; :func:`build_openapi` adds what generators need to do the
main tasks (submit a job, follow it, download its files), without changing any route's behaviour:

- uploads declared ``type: string, format: binary`` (FastAPI writes OpenAPI 3.1's
  ``contentMediaType: application/octet-stream``, which generators take for text);
- the bearer security scheme, always declared (required when the service has tokens, optional when not);
- ``MethodName`` and ``JobState`` enums, on the submit form's ``method`` and the jobs list's ``state``;
- every method's parameters as a component schema (``<Method>Params``, the engine's pydantic model),
  reachable from the submit operation: the ``params`` form field (a JSON string) carries them as its
  ``contentSchema``, and ``JobRequest`` is their union discriminated on ``method``.

Artifacts declare their real media types in the routes (app/api/routes/jobs.py); generators map
``image/png``/``image/tiff`` to bytes with docs/openapi-python-client.yaml.
"""

from __future__ import annotations

import copy
import re
from collections.abc import Callable, Mapping
from typing import Any

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi

from texsynth.synth.api import MethodSpec

__all__ = ["build_openapi", "install_openapi", "params_schema_name"]

_REF = "#/components/schemas/"


def params_schema_name(method: str) -> str:
    """``'wei-levoy'`` -> ``'WeiLevoyParams'``: the component schema of a method's parameters."""
    return "".join(part.capitalize() for part in re.split(r"[^0-9A-Za-z]+", method) if part) + "Params"


def install_openapi(app: FastAPI, methods: Callable[[], Mapping[str, MethodSpec]], *, tokens: bool) -> None:
    """Serve :func:`build_openapi`'s document as ``app.openapi()`` (built once, on first request)."""

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            base = get_openapi(
                title=app.title, version=app.version, description=app.description, routes=app.routes
            )
            app.openapi_schema = build_openapi(base, methods(), tokens=tokens)
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


def build_openapi(base: dict[str, Any], methods: Mapping[str, MethodSpec], *, tokens: bool) -> dict[str, Any]:
    """``base`` (FastAPI's document) with binary uploads, security, enums and per-method parameters."""
    schema = copy.deepcopy(base)
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    _binary_uploads(schema)
    names = sorted(methods)
    components["MethodName"] = {"type": "string", "enum": names, "title": "MethodName"}
    params_refs = _params_components(components, methods)
    components["JobRequest"] = {
        "title": "JobRequest",
        "description": "What a submission asks for: the method and its parameters (sent as the form fields "
        "'method' and 'params', the latter as a JSON string).",
        "oneOf": [{"$ref": _REF + f"JobRequest{params_schema_name(n)[:-6]}"} for n in names],
        "discriminator": {
            "propertyName": "method",
            "mapping": {n: _REF + f"JobRequest{params_schema_name(n)[:-6]}" for n in names},
        },
    }
    for name in names:
        components[f"JobRequest{params_schema_name(name)[:-6]}"] = {
            "type": "object",
            "title": f"JobRequest{params_schema_name(name)[:-6]}",
            "properties": {
                "method": {"type": "string", "const": name, "enum": [name]},
                "params": {"$ref": params_refs[name]},
            },
            "required": ["method"],
        }
    _submit_form(schema, params_refs)
    _state_query(schema)
    _security(schema, tokens=tokens)
    return schema


def _binary_uploads(node: Any) -> None:
    """Every ``contentMediaType: application/octet-stream`` string -> ``format: binary``, in place."""
    if isinstance(node, dict):
        if node.get("type") == "string" and node.get("contentMediaType") == "application/octet-stream":
            del node["contentMediaType"]
            node["format"] = "binary"
        for value in node.values():
            _binary_uploads(value)
    elif isinstance(node, list):
        for value in node:
            _binary_uploads(value)


def _params_components(components: dict[str, Any], methods: Mapping[str, MethodSpec]) -> dict[str, str]:
    """Each method's parameter model as ``<Method>Params`` (its ``$defs`` hoisted); name -> ``$ref``."""
    refs = {}
    for name, spec in sorted(methods.items()):
        model = spec.schema()
        model_name = params_schema_name(name)
        defs = model.pop("$defs", {})
        renamed = {key: f"{model_name}{key}" for key in defs}

        def fix(node: Any, renamed: dict[str, str] = renamed) -> Any:
            if isinstance(node, dict):
                out = {k: fix(v) for k, v in node.items()}
                ref = out.get("$ref")
                if isinstance(ref, str) and ref.startswith("#/$defs/"):
                    out["$ref"] = _REF + renamed[ref.removeprefix("#/$defs/")]
                return out
            if isinstance(node, list):
                return [fix(v) for v in node]
            return node

        for key, value in defs.items():
            components[renamed[key]] = fix(value)
        body = fix(model)
        body["title"] = model_name
        body["description"] = f"Parameters of method '{name}' ({spec.summary}). " + body.get(
            "description", ""
        )
        components[model_name] = body
        refs[name] = _REF + model_name
    return refs


def _submit_form(schema: dict[str, Any], params_refs: Mapping[str, str]) -> None:
    """The multipart forms with ``method`` and ``params``: an enum on one, per-method schemas on the other."""
    for operations in schema.get("paths", {}).values():
        for operation in operations.values():
            content = operation.get("requestBody", {}).get("content", {}).get("multipart/form-data")
            if not content:
                continue
            form = _resolve(schema, content["schema"])
            props = form.get("properties", {})
            if "method" in props:
                props["method"] = {
                    "$ref": _REF + "MethodName",
                    "description": props["method"].get("description", ""),
                }
            if "params" in props:
                props["params"]["contentMediaType"] = "application/json"
                props["params"]["contentSchema"] = {"oneOf": [{"$ref": ref} for ref in params_refs.values()]}
                props["params"]["description"] = (
                    props["params"].get("description", "")
                    + ". Its schema per method: the component <Method>Params (e.g. WeiLevoyParams), "
                    "JobRequest's member for the method, and GET /api/methods' params_schema."
                )


def _state_query(schema: dict[str, Any]) -> None:
    for operation in schema.get("paths", {}).get("/api/jobs", {}).values():
        for parameter in operation.get("parameters", []):
            if parameter.get("name") == "state" and parameter.get("in") == "query":
                parameter["schema"] = {
                    "anyOf": [{"$ref": _REF + "JobState"}, {"type": "null"}],
                    "title": "State",
                }


def _security(schema: dict[str, Any], *, tokens: bool) -> None:
    """The bearer scheme; required on every route but health with tokens, optional without."""
    schema["components"]["securitySchemes"] = {
        "bearer": {
            "type": "http",
            "scheme": "bearer",
            "description": "a token of TEXSYNTH_API_TOKENS (when the service has none, no token is needed)",
        }
    }
    requirement: list[dict[str, list[str]]] = [{"bearer": []}] if tokens else [{}, {"bearer": []}]
    unauthorised = {
        "description": "no token, or one the service does not know (when it has tokens)",
        "content": {"application/json": {"schema": {"$ref": _REF + "ErrorPublic"}}},
    }
    for path, operations in schema.get("paths", {}).items():
        if path != "/api/health":
            for operation in operations.values():
                operation["security"] = requirement
                operation.setdefault("responses", {}).setdefault("401", unauthorised)


def _resolve(schema: dict[str, Any], node: dict[str, Any]) -> dict[str, Any]:
    ref = node.get("$ref")
    if isinstance(ref, str) and ref.startswith(_REF):
        return schema["components"]["schemas"][ref.removeprefix(_REF)]
    return node
