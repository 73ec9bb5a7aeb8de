"""``/api/examples``: the bundled example exemplars (app/examples), their thumbnails and credits.

Public even with tokens, like ``/api/health``: they are the service's own files, the same for everyone,
and the page shows them as plain ``<img src>`` before anyone signs in.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Response
from fastapi.responses import FileResponse

from texsynth.app.examples import EXAMPLES, catalogue, thumbnail_png
from texsynth.app.schemas import ErrorPublic, ExamplePublic

router = APIRouter(prefix="/api/examples", tags=["examples"])

_NAME = Annotated[str, Path(description="an example's name from GET /api/examples")]
_PNG = {
    200: {
        "description": "a PNG image",
        "content": {"image/png": {"schema": {"type": "string", "format": "binary"}}},
    },
    404: {"model": ErrorPublic, "description": "no such example"},
}


def _example(name: str):
    if name not in EXAMPLES:
        raise HTTPException(404, f"no example {name!r}; examples: {', '.join(EXAMPLES)}")
    return EXAMPLES[name]


@router.get("", response_model=list[ExamplePublic])
def list_examples() -> list[dict]:
    """Every bundled example: title, kind (``2d`` exemplar or ``constraint``), credit and licence, the
    method that suits it, whether it has lattice fringes, and its image and thumbnail URLs."""
    return catalogue()


@router.get("/{name}", response_class=FileResponse, responses=_PNG)
def get_example(name: _NAME) -> FileResponse:
    """The example's PNG, to submit as an exemplar (or constraint)."""
    example = _example(name)
    return FileResponse(
        example.path,
        media_type="image/png",
        filename=example.path.name,
        headers={"Cache-Control": "max-age=86400"},
    )


@router.get("/{name}/thumbnail", response_class=Response, responses=_PNG)
def get_thumbnail(name: _NAME) -> Response:
    """A small PNG of the example for the gallery."""
    _example(name)
    return Response(thumbnail_png(name), media_type="image/png", headers={"Cache-Control": "max-age=86400"})
