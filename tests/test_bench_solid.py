"""benchmarks.bench_solid: a run rewrites what it measures and keeps docs/solid.md's hand-written part."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from benchmarks import bench_solid as bs

DOC = """# Solid textures

Intro.

## ex

| method | scan |
|---|---|
| `solid-kopf` | lexicographic | old |
| `solid-kopf` | random | old |
| `solid-kopf` | morton | old |
| `solid-kopf` | hilbert | old |
| `solid-chen-wang` | hilbert | other |

## Laminae and one exemplar for three planes

old extras

## Fast against exact search (24^3)

fast table

## Laminar HRTEM: the structure first (issue 24)

hand-written 1

### A later session's section

hand-written 2

## Verdict

verdict by hand

## Speed and memory (2 cores)

speed table
"""


def test_kept_parts_splits_the_file() -> None:
    parts = bs.kept_parts(DOC)
    assert parts["extras"].startswith("## Laminae and one exemplar") and "fast table" in parts["extras"]
    assert parts["fast"] == "## Fast against exact search (24^3)\n\nfast table"
    assert parts["kept"].startswith("## Laminar HRTEM") and parts["kept"].endswith("verdict by hand")
    assert parts["speed"] == "## Speed and memory (2 cores)\n\nspeed table"
    assert bs.kept_parts("# only a title\n") == {"extras": "", "fast": "", "kept": "", "speed": ""}


def test_refresh_rewrites_one_method_and_keeps_the_hand_written_part(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bs, "exemplars", lambda: {"ex": np.zeros((4, 4), dtype=np.float32)})

    def run_row(method: str, scan: str, exemplar: np.ndarray) -> dict[str, Any]:
        return {"seconds": 0.0, "volume": None, "scan": scan}

    monkeypatch.setattr(bs, "run_row", run_row)
    monkeypatch.setattr(
        bs, "table", lambda rows: f"| h |\n| `{rows[0]['method']}` | {rows[0]['scan']} | new |"
    )
    monkeypatch.setattr(bs, "save_image", lambda *a, **k: None)
    monkeypatch.setattr(bs, "slices_figure", lambda *a, **k: None)
    monkeypatch.setattr(
        bs, "_extra_sections", lambda: ["## Laminae and one exemplar for three planes\n\nnew extras"]
    )
    out = bs.refresh("solid-kopf", DOC)
    for scan in bs.SCANS:
        assert f"| `solid-kopf` | {scan} | new |" in out
    assert "| `solid-chen-wang` | hilbert | other |" in out and "old |" not in out
    assert "new extras" in out and "old extras" not in out
    parts = bs.kept_parts(DOC)
    assert parts["fast"] in out and parts["kept"] in out and out.rstrip().endswith(parts["speed"])
    assert out.index("new extras") < out.index("fast table") < out.index("hand-written 1")
    assert "re-run after a change to that method alone" in out
