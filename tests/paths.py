"""Where the tests find the project's shared data: ``shared/data`` beside the checkout (as in CI),
else the workplace's ``/work/shared/data``."""

from __future__ import annotations

from pathlib import Path

_BESIDE = Path(__file__).resolve().parents[2] / "shared" / "data"
SHARED_DATA = _BESIDE if _BESIDE.is_dir() else Path("/work/shared/data")
