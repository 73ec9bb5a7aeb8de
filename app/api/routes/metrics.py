"""``/api/metrics``: what each headline measure means, its direction and its documented threshold."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from texsynth.synth.evaluate.glossary import glossary

router = APIRouter(prefix="/api/metrics", tags=["metrics"])


@router.get("")
def list_measures() -> dict[str, dict[str, Any]]:
    """``{name: {label, meaning, better, good_below, unit}}`` for every headline measure."""
    return glossary()
