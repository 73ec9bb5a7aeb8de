"""Tileable outputs (``periodic=True``): the seam at the tile borders of a 2 x 2 tiling, without and with.

Run ``python -m benchmarks.bench_tileable [--methods quilting,gaussian-patch] [--seeds 3]``; writes the
``tileable`` section of docs/quality.md (between ``<!-- begin:tileable -->`` and ``<!-- end:tileable -->``,
appended at the end when absent) and docs/img/tileable-<method>.png (soot, seed 1: the 2 x 2 tiling of the
output with ``periodic=False``, then with ``periodic=True``). Rows of methods not run this time are kept
from the section as it was, so the slow pixel methods can be measured separately.

Every 2D method in :data:`METHODS` whose parameters accept ``periodic`` (the others are skipped, with a
message), with its defaults, 128 x 128 exemplars -> 256 x 256, seeds 1-3, on HRTEM soot
(``hrtem-soot-128.png`` in the shared data) and the public ``skimage.data`` gravel and brick crops
(``[:128, :128] / 255``). Methods that need a constraint image get a periodic wave pattern of the
output's size. Measure: :func:`texsynth.synth.evaluate.tile_seam` of each output: ``ratio`` (the tile borders'
gradient energy over the interior's, 1 = alike) and the ranks of the two borders among the image's own
lines of pixel pairs (about 0.5 seamless, 1.0 = a seam stronger than any line inside). Cells: mean ratio
over the seeds (worst seed in brackets) and each rank's largest value over the seeds; times are medians
per run, seconds.
"""

from __future__ import annotations

import argparse
import re
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from skimage import data as skdata

from benchmarks._report import DATA, write_section
from texsynth.synth.api import find_method, synthesize
from texsynth.synth.evaluate import tile_seam
from texsynth.synth.io import load_image, save_image

DOCS = Path(__file__).resolve().parent.parent / "docs"
DOC = DOCS / "quality.md"
SECTION = "tileable"
SIZE = (256, 256)
#: Every 2D method; those whose parameters have no ``periodic`` yet are skipped.
METHODS = (
    "wei-levoy",
    "tensor-constrained",
    "arbitrary-shape",
    "quilting",
    "gaussian-patch",
    "feature-guided",
    "random-phase",
)
HEAD = (
    "| method | exemplar | ratio, periodic=False | ranks (rows / cols) | ratio, periodic=True | "
    "ranks (rows / cols) | time (s) False / True |"
)
SEP = "|---|---|---|---|---|---|---|"


#: What the table does not say (measured when this benchmark was written; see the commit messages).
NOTES = (
    "How: the patch methods lay their patches on the output's torus (`texsynth.synth.patch.layout`, periodic "
    "layout); the last column / row of patches is searched and cut against its left *and* right / top "
    "*and* bottom strips; `gaussian-patch` re-solves the new part of those two-sided patches so that it "
    "meets its strips without a jump (`texsynth.synth.patch.gaussian.mend_inner_edges`); random-phase noise "
    "is "
    "periodic by construction (`periodic=True` only changes outputs smaller than the exemplar). The pixel "
    "methods' neighbourhoods always wrapped, but a causal scan ends at the bottom and right borders without "
    "ever matching the first rows and columns it touches in a tiling: with `periodic=True` the first pass "
    "also compares the already-made pixels across the border, the later passes compare full square "
    "neighbourhoods in random order, and `arbitrary-shape` wraps its constraint's tensors, S_en and "
    "guidance pyramid (the output tiles when the constraint does).",
    "",
    "Reading the ratios: one line of pixel pairs is a noisy sample. On gravel and brick, 91-98 % of "
    "`quilting`'s wrap-around pairs are verbatim continuations of the exemplar (the cuts lie elsewhere in "
    "the strips), so ratios above 1 there come from stone edges and mortar joints that happen to lie along "
    "the border (brick's strongest interior lines reach 5-7 times the mean; over 8 seeds the border averaged "
    "1.08 +- 0.09 on gravel, 1.75 +- 0.42 on brick). Limit seen in the pictures: `gaussian-patch` on brick "
    "cannot fit joints on both sides of its last column / row with N = 5 neighbours (broken joints there), "
    "and the mending smears a joint that only one side has. `tensor-constrained` on brick tiles since its "
    "brick defaults (flat neighbourhoods for exemplars oriented in two directions, LE, pixel-only "
    "refinement: periodic ratio 3.98 -> 0.72; docs/tensor-constrained.md); a few joint stubs remain inside. "
    "`arbitrary-shape` on brick gets its strand hints (brick's fibre grey spread is above the threshold): "
    "the joints are laid along the wave grating as dashed lines, and one seed in three shows its "
    "horizontal tile border (rows ratio 2.16, seed 1; 0.73-1.07 otherwise); brick, oriented two ways, "
    "cannot follow a one-way constraint as fibres do.",
)


def exemplars() -> dict[str, np.ndarray]:
    """HRTEM soot (when the shared data is there), gravel and brick: 128 x 128 grey in [0, 1]."""
    out: dict[str, np.ndarray] = {}
    soot = DATA / "hrtem-soot-128.png"
    if soot.exists():
        out["soot"] = load_image(soot)
    else:
        print(f"no {soot}: soot skipped", flush=True)
    for name in ("gravel", "brick"):
        img = getattr(skdata, name)()[:128, :128]
        out[name] = (img if img.ndim == 2 else img.mean(axis=2)).astype(np.float32) / 255.0
    return out


def periodic_constraint(size: tuple[int, int]) -> np.ndarray:
    """A wavy grating that tiles at ``size`` (whole numbers of periods along both axes)."""
    yy, xx = np.mgrid[0 : size[0], 0 : size[1]].astype(np.float64)
    bend = 8.0 * np.sin(2 * np.pi * yy / (size[0] / 2))
    return (0.5 + 0.5 * np.sin(2 * np.pi * (xx + bend) / (size[1] / 8))).astype(np.float32)


def accepts_periodic(method: str) -> bool:
    spec = find_method(method)
    return spec is not None and "periodic" in spec.params_model.model_fields


def tiling(image: np.ndarray) -> np.ndarray:
    """The 2 x 2 tiling of an output."""
    return np.tile(image, (2, 2) if image.ndim == 2 else (2, 2, 1))


def figure(plain: np.ndarray, periodic: np.ndarray) -> np.ndarray:
    """The two 2 x 2 tilings side by side, a 8 px white gutter."""
    a, b = tiling(plain), tiling(periodic)
    gutter = np.ones((a.shape[0], 8, *a.shape[2:]), dtype=np.float32)
    return np.concatenate([a, gutter, b], axis=1)


def run(method: str, exemplar: np.ndarray, periodic: bool, seed: int) -> tuple[np.ndarray, float]:
    spec = find_method(method)
    assert spec is not None
    constraint = periodic_constraint(SIZE) if spec.constraint == "required" else None
    start = time.perf_counter()
    result = synthesize(
        method, exemplar, size=SIZE, params={"periodic": periodic}, seed=seed, constraint=constraint
    )
    return result.image, time.perf_counter() - start


def row(
    method: str, exemplar: str, runs: dict[bool, list[dict[str, float]]], times: dict[bool, list[float]]
) -> str:
    cells = []
    for periodic in (False, True):
        ratios = [m["ratio"] for m in runs[periodic]]
        cells.append(f"{statistics.mean(ratios):.2f} ({max(ratios):.2f})")
        worst = (max(m[key] for m in runs[periodic]) for key in ("rows_rank", "cols_rank"))
        cells.append(" / ".join(f"{r:.2f}" for r in worst))
    t = " / ".join(f"{statistics.median(times[p]):.1f}" for p in (False, True))
    return f"| `{method}` | {exemplar} | " + " | ".join(cells) + f" | {t} |"


def previous_rows() -> dict[tuple[str, str], str]:
    """The table rows of the section as it is, by (method, exemplar)."""
    if not DOC.exists():
        return {}
    match = re.search(rf"<!-- begin:{SECTION} -->(.*?)<!-- end:{SECTION} -->", DOC.read_text(), re.S)
    rows: dict[tuple[str, str], str] = {}
    for line in (match.group(1) if match else "").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| `") and len(cells) >= 2:
            rows[(cells[0].strip("`"), cells[1])] = line
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--methods",
        default=",".join(METHODS),
        help="comma-separated methods to run (default: all of METHODS; the pixel methods are slow)",
    )
    parser.add_argument("--seeds", type=int, default=3, help="seeds 1..N (default 3)")
    args = parser.parse_args(argv)
    wanted = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in wanted if m not in METHODS]
    if unknown:
        parser.error(f"unknown methods {unknown}; choose among {', '.join(METHODS)}")
    seeds = tuple(range(1, args.seeds + 1))
    (DOCS / "img").mkdir(parents=True, exist_ok=True)
    rows = previous_rows()
    skipped = []
    started = time.perf_counter()
    for method in wanted:
        if not accepts_periodic(method):
            print(f"{method}: skipped, its parameters do not accept 'periodic' yet", flush=True)
            skipped.append(method)
            continue
        for name, exemplar in exemplars().items():
            runs: dict[bool, list[dict[str, float]]] = {False: [], True: []}
            times: dict[bool, list[float]] = {False: [], True: []}
            first: dict[bool, np.ndarray] = {}
            for periodic in (False, True):
                for seed in seeds:
                    image, seconds = run(method, exemplar, periodic, seed)
                    runs[periodic].append(tile_seam(image))
                    times[periodic].append(seconds)
                    first.setdefault(periodic, image)
            rows[(method, name)] = row(method, name, runs, times)
            print(rows[(method, name)], flush=True)
            if name == "soot":
                save_image(DOCS / "img" / f"tileable-{method}.png", figure(first[False], first[True]))
    order = {m: i for i, m in enumerate(METHODS)}
    names = ("soot", "gravel", "brick")
    table = sorted(
        rows.items(),
        key=lambda kv: (order.get(kv[0][0], 99), names.index(kv[0][1]) if kv[0][1] in names else 9),
    )
    pictures = [m for m in METHODS if (DOCS / "img" / f"tileable-{m}.png").exists()]
    not_yet = [m for m in METHODS if not any(key[0] == m for key in rows)]
    markdown = [
        "## Tileable outputs (`periodic=True`)",
        "",
        "Generated by `python -m benchmarks.bench_tileable` (its docstring defines the cells). 128 x 128 "
        f"exemplars -> 256 x 256, defaults, seeds {seeds[0]}-{seeds[-1]}; "
        f"`texsynth.synth.evaluate.tile_seam` of each "
        "output: ratio = gradient energy across the borders of a 2 x 2 tiling over the interior's (1 = "
        "alike; mean over seeds, worst in brackets), ranks = share of the image's own lines of pixel pairs "
        "weaker than each border, the largest over the seeds (about 0.5 seamless, 1.0 = a seam stronger "
        "than any line inside).",
        "",
        HEAD,
        SEP,
        *[line for _, line in table],
    ]
    markdown += ["", *NOTES]
    if not_yet:
        markdown += [
            "",
            "Not measured yet (no `periodic` parameter, or not run): "
            + ", ".join(f"`{m}`" for m in not_yet)
            + ".",
        ]
    for method in pictures:
        markdown += [
            "",
            f"`{method}`, soot, seed 1: the 2 x 2 tiling with `periodic=False` (left) and `periodic=True` "
            "(right).",
            "",
            f"![tileable {method}](img/tileable-{method}.png)",
        ]
    ran = [m for m in wanted if m not in skipped]
    print(f"{', '.join(ran) or 'nothing'} measured in {time.perf_counter() - started:.0f} s", flush=True)
    write_section(SECTION, "\n".join(markdown), doc=DOC)
    print(f"wrote the {SECTION} section of {DOC}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
