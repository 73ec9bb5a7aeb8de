"""``texsynth methods [--json]``: the synthesis methods this engine knows, with their parameters.

The list comes from :func:`texsynth.synth.api.available_methods`; each method's parameters are its pydantic
model's JSON schema (:meth:`texsynth.synth.api.MethodSpec.schema`), the same schema the service publishes, so
the command line never describes a parameter a second time.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from texsynth.synth.api import MethodSpec

__all__ = ["describe", "register", "run"]


def available_methods() -> dict[str, MethodSpec]:
    """:func:`texsynth.synth.api.available_methods`, imported when the command runs (``--help`` imports no
    method)."""
    from texsynth.synth.api import available_methods as registered

    return registered()


def describe(spec: MethodSpec) -> dict[str, Any]:
    """A method as a JSON-ready dict: name, summary, paper, inputs, constraint, output_ndim, schema."""
    return {
        "name": spec.name,
        "summary": spec.summary,
        "paper": spec.paper,
        "inputs": spec.inputs,
        "constraint": spec.constraint,
        "output_ndim": spec.output_ndim,
        "schema": spec.schema(),
    }


def _parameter_lines(schema: dict[str, Any]) -> list[str]:
    """``name (type, default X): description`` for every property of a JSON schema."""
    lines = []
    for name, prop in schema.get("properties", {}).items():
        kind = prop.get("type") or "/".join(p.get("type", "?") for p in prop.get("anyOf", [])) or "value"
        if "enum" in prop:
            kind = " | ".join(json.dumps(v) for v in prop["enum"])
        detail = f"{kind}, default {json.dumps(prop['default'])}" if "default" in prop else kind
        text = prop.get("description") or prop.get("title", "")
        lines.append(f"    {name} ({detail}){': ' + text if text else ''}")
    return lines


def run(args: argparse.Namespace) -> int:
    """List the methods, as text or (``--json``) as a JSON array on stdout."""
    described = [describe(spec) for _, spec in sorted(available_methods().items())]
    if args.json:
        json.dump(described, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    if not described:
        print("no synthesis methods are registered")
        return 0
    for item in described:
        extra = {"required": ", needs a constraint image", "optional": ", optional constraint image"}
        volume = ", output is a volume" if item["output_ndim"] == 3 else ""
        if "exemplar_xy" in item["inputs"]:
            volume += " (one exemplar, or --exemplar-xy/-xz/-yz for an anisotropic material)"
        print(f"{item['name']}: {item['summary']}{extra.get(item['constraint'], '')}{volume}")
        if item["paper"]:
            print(f"  paper: {item['paper']}")
        print("  parameters:")
        print("\n".join(_parameter_lines(item["schema"])) or "    (none)")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``methods`` to the ``texsynth`` command line."""
    parser = subparsers.add_parser(
        "methods",
        help="list the synthesis methods and their parameters",
        description="List the synthesis methods with their parameters (defaults = the papers' settings).",
    )
    parser.add_argument(
        "--json", action="store_true", help="print a JSON array: name, summary, paper, constraint, schema"
    )
    parser.set_defaults(func=run)
