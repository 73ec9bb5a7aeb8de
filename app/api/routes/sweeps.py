"""``/api/sweeps``: run a parameter grid as a Celery group and collect all metrics in one table."""

from __future__ import annotations

import csv
import io
from typing import Annotated

from fastapi import APIRouter, Form, HTTPException, Query, Response

from texsynth.app.api.deps import PrincipalDep, ServiceDep
from texsynth.app.api.routes.jobs import _ERRORS, SizeDep, UploadsDep
from texsynth.app.schemas import ErrorPublic, SweepPublic

router = APIRouter(prefix="/api/sweeps", tags=["sweeps"])


@router.post("", status_code=202, response_model=SweepPublic, responses=_ERRORS)
def submit_sweep(
    service: ServiceDep,
    principal: PrincipalDep,
    response: Response,
    uploads: UploadsDep,
    size: SizeDep,
    method: Annotated[str, Form(min_length=1, description="a method name from GET /api/methods")],
    grid: Annotated[
        str, Form(description='JSON: parameter -> list of values, e.g. {"neighbourhood": [5, 9]}')
    ] = "{}",
    params: Annotated[str, Form(description="JSON: fixed parameters of every run")] = "{}",
    seed: Annotated[int | None, Form()] = None,
) -> dict:
    """One job per point of ``grid`` (the product of its lists; ``width``/``height``/``depth`` may be
    swept too), sharing the inputs and the seed."""
    request = service.validate(method, params, seed, uploads, size)
    sweep_id = service.submit_sweep(request, grid, principal)
    response.headers["Location"] = f"/api/sweeps/{sweep_id}"
    sweep = service.store.get_sweep(sweep_id)
    return service.sweep_public(sweep)


@router.get("/{sweep_id}", response_model=SweepPublic, responses={404: {"model": ErrorPublic}})
def get_sweep(
    service: ServiceDep,
    principal: PrincipalDep,
    sweep_id: str,
    format: Annotated[str, Query(pattern="^(json|csv)$")] = "json",
):
    """The sweep's table: one row per run with its grid values and metrics (``?format=csv`` for CSV)."""
    sweep = service.visible_sweep(sweep_id, principal)
    if sweep is None:
        raise HTTPException(404, f"no sweep with id {sweep_id!r}")
    public = service.sweep_public(sweep)
    if format == "csv":
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=public["columns"], extrasaction="ignore")
        writer.writeheader()
        writer.writerows(public["rows"])
        return Response(buf.getvalue(), media_type="text/csv")
    return public
