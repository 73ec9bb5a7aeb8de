"""The real crops' starting sheets in docs/solid.md: the table of benchmarks.bench_sheets."""

from __future__ import annotations

from benchmarks import bench_sheets
from benchmarks.bench_laminar import AXES, MEASURES


def _rows(value: float, shells: str, spacing: float | None = None) -> list[dict]:
    axes = {a: {key: value for key, *_ in MEASURES} for a in AXES}
    for a in AXES:
        axes[a]["coherence_ratio"] = axes[a]["contrast"] = 1.0
    return [
        {"seed": s, "cpu": 3.0, "wall": 2.0 + s, "shells": shells, "spacing": spacing, "axes": axes}
        for s in (1, 2, 3)
    ]


def _crop(sheets: str, auto: str) -> dict:
    return {
        "file": "hrtem-x-128.png",
        "bend": 1.95,
        "concentration": 0.0,
        "concentric": 0.76,
        "sheets": sheets,
        "auto": auto,
        "rows": {
            "solid-kopf default": _rows(0.05, sheets, 2.0 if sheets == "domains" else 4.4),
            "solid-kopf surfaces": _rows(0.2, "surfaces"),
            "solid-kopf domains 2.5": _rows(0.05, "domains"),
            "solid-chen-wang default": _rows(0.05, auto),
        },
    }


def test_the_table_marks_each_crops_default_and_its_misses() -> None:
    saved = {
        "machine": "2 cores",
        "crops": {"x": _crop("domains", "domains"), "y": _crop("surfaces", "centres")},
    }
    text = bench_sheets.report(saved)
    lines = [line for line in text.splitlines() if line.startswith("| x") or line.startswith("| y")]
    assert len(lines) == 8
    x_default, x_surfaces, x_domains, x_cw, y_default, y_surfaces, y_domains, _ = lines
    assert "| x (1.95: domains; auto domains) | solid-kopf surfaces |" in x_surfaces
    # a default row names the start it took, with the domains' spacing
    assert "| solid-kopf default (domains 2) |" in x_default and "default" not in x_surfaces
    assert "| solid-kopf domains 2.5 |" in x_domains
    assert "solid-chen-wang default (domains)" in x_cw
    assert "| solid-kopf default (surfaces) |" in y_default and "default" not in y_surfaces + y_domains
    # 0.2 misses every "below" target (**x**), 0.05 none; the ratios at 1.0 never
    assert x_surfaces.count("**x**") == 4 and "**x**" not in x_domains
    assert x_domains.endswith("| 4.0 |")  # the median wall time of the seeds (3, 4, 5 s)
    assert "img/sheets-hrtem-x-128-surfaces.png" in text and "seeds 1, 2, 3, 64^3" in text


def test_every_crop_is_its_window_of_the_whole_image() -> None:
    """The shipped crops (and ../shared's soot-256, when present) are the windows ``--shifts`` moves."""
    import numpy as np

    from texsynth.synth.io import load_image

    whole = np.asarray(load_image(bench_sheets.SOURCE, mode="grey"))
    assert whole.shape == (512, 512) and set(bench_sheets.WINDOWS) == set(bench_sheets.CROPS)
    for name, (row, col, side) in bench_sheets.WINDOWS.items():
        path = bench_sheets.CROPS[name]
        if not path.exists():
            continue
        crop = np.asarray(load_image(path, mode="grey"))
        np.testing.assert_array_equal(crop, whole[row : row + side, col : col + side], err_msg=name)
