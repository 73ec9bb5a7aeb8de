"""``/api/methods``: the methods and their parameter JSON schemas (from the engine's pydantic models)."""

from __future__ import annotations

from fastapi import APIRouter

from texsynth.app.api.deps import ServiceDep
from texsynth.app.schemas import MethodsPublic

router = APIRouter(prefix="/api/methods", tags=["methods"])


@router.get("", response_model=MethodsPublic)
def list_methods(service: ServiceDep) -> dict:
    """Every method with its parameter schema (defaults = the papers' settings) and output size fields."""
    data = [
        {
            "name": spec.name,
            "summary": spec.summary,
            "paper": spec.paper,
            "inputs": spec.inputs,
            "constraint": spec.constraint,
            "output_ndim": spec.output_ndim,
            "params_schema": spec.schema(),
            "size_schema": service.size_schema(spec),
        }
        for spec in sorted(service.methods().values(), key=lambda s: s.name)
    ]
    return {"data": data, "count": len(data)}
