"""The solids' grain on real and known laminar exemplars: ``solid-chen-wang``'s discrete last step against
its grain-matched one (issue 24).

Run: ``python -m benchmarks.bench_grain`` (writes docs/grain-crops.json, the section ``grain`` of
docs/solid.md and docs/img/grain-*.png); ``--report`` rewrites the section from the JSON alone.

Grain is :func:`texsynth.synth.analysis.grain.fine_share` (the share of a slice's variance finer than a 1 px
Gaussian), over every fourth slice along each axis, divided by the exemplar's: 1 = as grainy as the
exemplar; the discrete solver's copies speckle a smooth HRTEM crop (2x), which the grey histogram (kept by the
rank remap), the structure tensor (smoothed) and the fringe statistics do not show. For each exemplar (the
real crops of ``bench_sheets``, the study's soot-128, and the mid-slices of the known onion and turbostratic
volumes of ``bench_laminar``), 64^3 with one exemplar for the three planes, seeds 1-3: ``solid-chen-wang``
with ``final_step='discrete'`` (the paper; the default before) and its default (``'auto'``), and
``solid-kopf``'s default for reference. Cells ``xy / xz / yz`` means over the seeds (worst seed-axis) as in
``bench_sheets``; grain is the mean (worst). Pictures: seed 1's xy mid-slice of each run beside a 64^2 crop of
the exemplar, 3x, no smoothing.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np
from PIL import Image

from benchmarks._report import DATA, machine, write_section
from benchmarks.bench_laminar import DOCS, MEASURES, _cells, against_exemplars, exemplars, truths
from benchmarks.bench_sheets import CROPS
from texsynth.synth.analysis.grain import fine_share
from texsynth.synth.api import synthesize
from texsynth.synth.io import load_image

RESULTS = DOCS / "grain-crops.json"
SIDE = 64
SEEDS = (1, 2, 3)
RUNS = {
    "solid-chen-wang discrete (paper, before)": ("solid-chen-wang", {"final_step": "discrete"}),
    "solid-chen-wang default": ("solid-chen-wang", {}),
    "solid-kopf default": ("solid-kopf", {}),
}
#: Slices compared per axis: every this many.
SLICE_STEP = 4
ZOOM = 3


def grain_ratio(volume: np.ndarray, exemplar: np.ndarray) -> list[float]:
    """Per axis, the mean fine share of every :data:`SLICE_STEP`-th slice over the exemplar's."""
    target = fine_share(exemplar)
    out = []
    for a in range(3):
        shares = [fine_share(np.take(volume, i, axis=a)) for i in range(0, volume.shape[a], SLICE_STEP)]
        out.append(float(np.mean(shares)) / target)
    return out


def exemplar_images() -> dict[str, tuple[str, np.ndarray]]:
    """name -> (file stem, grey exemplar): the real crops, soot-128 and the truths' xy mid-slices."""
    out = {
        name: (path.stem, np.ascontiguousarray(load_image(path, mode="grey"), dtype=np.float32))
        for name, path in {**CROPS, "soot-128": DATA / "hrtem-soot-128.png"}.items()
    }
    for family, truth in truths().items():
        out[f"{family} truth (mid-slice)"] = (f"truth-{family}", exemplars(truth, "one")["xy"])
    return out


def _picture(image: np.ndarray, volumes: list[np.ndarray]) -> np.ndarray:
    """The exemplar's top-left 64^2 and each volume's xy mid-slice, side by side, :data:`ZOOM` times."""
    tiles = [image[:SIDE, :SIDE], *(v[SIDE // 2] for v in volumes)]
    gap = np.full((SIDE, 2), 1.0, dtype=np.float32)
    row = np.concatenate([part for t in tiles for part in (t.astype(np.float32), gap)][:-1], axis=1)
    grey = (np.clip(row, 0.0, 1.0) * 255).round().astype(np.uint8)
    return np.kron(grey, np.ones((ZOOM, ZOOM), dtype=np.uint8))


def run() -> dict[str, Any]:
    out: dict[str, Any] = {"machine": machine(), "exemplars": {}}
    for name, (stem, image) in exemplar_images().items():
        planes = dict.fromkeys(("xy", "xz", "yz"), image)
        entry: dict[str, Any] = {"stem": stem, "rows": {}}
        firsts = []
        for key, (method, params) in RUNS.items():
            rows = []
            for seed in SEEDS:
                wall = time.perf_counter()
                result = synthesize(method, exemplars=planes, size=(SIDE,) * 3, params=params, seed=seed)
                wall = time.perf_counter() - wall
                rows.append(
                    {
                        "seed": seed,
                        "wall": wall,
                        "shells": result.stats.get("shells"),
                        "final_blend": result.stats.get("final_blend"),
                        "grain": grain_ratio(result.image, image),
                        "axes": against_exemplars(image, result.image),
                    }
                )
                if seed == SEEDS[0]:
                    firsts.append(result.image)
            entry["rows"][key] = rows
            print(f"{name}: {key} done", flush=True)
        Image.fromarray(_picture(image, firsts)).save(DOCS / "img" / f"grain-{stem}.png")
        out["exemplars"][name] = entry
    RESULTS.write_text(json.dumps(out, indent=1) + "\n")
    return out


def report(saved: dict[str, Any]) -> str:
    head = "| exemplar | run | grain | blend | " + " | ".join(label for _, label, *_ in MEASURES) + " |"
    lines = [head, "|" + "---|" * (len(MEASURES) + 4)]
    pictures = []
    for name, entry in saved["exemplars"].items():
        for key, rows in entry["rows"].items():
            grains = [g for r in rows for g in r["grain"]]
            grain = f"{np.mean(grains):.2f} ({max(grains):.2f})"
            blends = [r["final_blend"] for r in rows if r["final_blend"] is not None]
            blend = f"{min(blends):.2f}-{max(blends):.2f}" if blends else ""
            shells = rows[0]["shells"]
            run = f"{key} ({shells})" if shells else key
            lines.append(f"| {name} | {run} | {grain} | {blend} | " + " | ".join(_cells(rows)) + " |")
        pictures.append(f"![{name}: exemplar, discrete, default, solid-kopf](img/grain-{entry['stem']}.png)")
    foot = f"_Measured on {saved['machine']}; seeds {', '.join(map(str, SEEDS))}, {SIDE}^3._"
    return "\n".join([*lines, "", foot, "", *pictures])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--report", action="store_true", help="rewrite the docs from the saved JSON")
    args = parser.parse_args(argv)
    saved = json.loads(RESULTS.read_text()) if args.report else run()
    markdown = report(saved)
    print(markdown)
    write_section("grain", markdown, DOCS / "solid.md")


if __name__ == "__main__":
    main()
