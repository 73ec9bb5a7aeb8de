"""The patch family: image quilting, LG / CLG / RCLG (Raad et al. 2015) and random-phase noise.

Run ``python -m benchmarks.bench_patch``; writes docs/patch.md (figures like the paper's Figs 2 and 3 in
docs/img/patch-*.png, and the tables of its claims) and the ``patch`` section of docs/benchmarks.md.
Exemplars: 128 x 128 crops of scikit-image's ``brick`` (periodic), ``grass`` (pseudo-periodic), ``gravel``
(macro-texture) and the shared HRTEM soot image; outputs 256 x 256, (w, N) = (30, 20) (the paper's
first pair), seed 0. OpenBLAS runs single-threaded here (set before NumPy loads): on the shared 2-core
machine its threads spin against the other jobs and make small matrix products several times slower.
"""

from __future__ import annotations

from synth.threads import single_threaded_blas

single_threaded_blas()  # before NumPy loads OpenBLAS

import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import skimage.data
from PIL import Image, ImageDraw

from benchmarks._report import DATA, median_time, write_section
from synth.api import synthesize
from synth.evaluate import COPY_THRESHOLD, evaluate_pair, seam_visibility
from synth.io import load_image

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "patch.md"
IMG = ROOT / "docs" / "img"
SIZE = (256, 256)
W, N = 30, 20
SEED = 0
#: The paper's estimate (the conditional mode); the method's default is estimate='neighbour' (a departure).
GAUSS = {"patch_size": W, "neighbours": N, "estimate": "mean"}
QUILT = {"patch_size": W}


def exemplars() -> dict[str, np.ndarray]:
    def crop(image: np.ndarray) -> np.ndarray:
        return (image[:128, :128] / 255.0).astype(np.float32)

    return {
        "brick": crop(skimage.data.brick()),
        "grass": crop(skimage.data.grass()),
        "gravel": crop(skimage.data.gravel()),
        "hrtem-soot-128": load_image(DATA / "hrtem-soot-128.png", mode="grey"),
    }


#: The paper's models literally (no contrast restoration): the claims are about them.
PAPER = {**GAUSS, "contrast": "none"}
#: The runs of each figure: label -> (method, params).
RUNS: dict[str, tuple[str, dict[str, Any]]] = {
    "quilting": ("quilting", QUILT),
    "LG": ("gaussian-patch", {**PAPER, "model": "lg"}),
    "CLG": ("gaussian-patch", {**PAPER, "model": "clg"}),
    "RCLG": ("gaussian-patch", {**PAPER, "model": "rclg"}),
    "random phase": ("random-phase", {}),
    "LG + cut": ("gaussian-patch", {**PAPER, "model": "lg", "blending": "boundary-cut"}),
    "CLG + cut": ("gaussian-patch", {**PAPER, "model": "clg", "blending": "boundary-cut"}),
    "RCLG + cut": ("gaussian-patch", {**PAPER, "model": "rclg", "blending": "boundary-cut"}),
    "quilting, graph cut": ("quilting", {**QUILT, "blending": "graph-cut"}),
    "RCLG draw": ("gaussian-patch", {**PAPER, "model": "rclg", "estimate": "draw"}),
    "RCLG draw + cut": (
        "gaussian-patch",
        {**PAPER, "model": "rclg", "estimate": "draw", "blending": "boundary-cut"},
    ),
    "RCLG, 2 scales": ("gaussian-patch", {**PAPER, "model": "rclg", "scales": 2}),
    "RCLG + cut, 2 scales": (
        "gaussian-patch",
        {**PAPER, "model": "rclg", "blending": "boundary-cut", "scales": 2},
    ),
    # the default: contrast restored (a departure, synth.patch.gaussian.restore_contrast)
    "CLG, restored": ("gaussian-patch", {**GAUSS, "model": "clg"}),
    "RCLG, restored": ("gaussian-patch", {**GAUSS, "model": "rclg"}),
    "RCLG + cut, restored": ("gaussian-patch", {**GAUSS, "model": "rclg", "blending": "boundary-cut"}),
    # the method's defaults: contrast restored, N = 5 nearest patches and the corrected-neighbour estimate
    # (departures, synth.methods.gaussian_patch)
    "RCLG + cut, defaults (N = 5, neighbour)": (
        "gaussian-patch",
        {"model": "rclg", "blending": "boundary-cut"},
    ),
    "RCLG + cut, N = 5, mean": (
        "gaussian-patch",
        {"model": "rclg", "blending": "boundary-cut", "estimate": "mean"},
    ),
}
FIDELITY = (
    "RCLG + cut, defaults (N = 5, neighbour)",
    "RCLG + cut, N = 5, mean",
    "RCLG + cut, restored",
    "RCLG, restored",
    "CLG, restored",
    "RCLG + cut",
    "RCLG",
    "RCLG + cut, 2 scales",
    "RCLG draw + cut",
    "quilting",
    "random phase",
)
FIGURE = [
    ["input", "quilting", "LG", "CLG", "RCLG"],
    ["random phase", "quilting, graph cut", "LG + cut", "CLG + cut", "RCLG + cut"],
    [
        "RCLG + cut, defaults (N = 5, neighbour)",
        "CLG, restored",
        "RCLG, restored",
        "RCLG + cut, restored",
        "RCLG draw + cut",
    ],
]


def gradient_energy(image: np.ndarray) -> float:
    g = image.astype(np.float64)
    return float((np.diff(g, axis=0) ** 2).mean() + (np.diff(g, axis=1) ** 2).mean())


def figure(name: str, exemplar: np.ndarray, images: dict[str, np.ndarray]) -> Path:
    pad, label_h = 6, 16
    tile = SIZE[0]
    rows, cols = len(FIGURE), len(FIGURE[0])
    canvas = Image.new("L", (cols * (tile + pad) + pad, rows * (tile + pad + label_h) + pad), 255)
    draw = ImageDraw.Draw(canvas)
    for r, row in enumerate(FIGURE):
        for c, label in enumerate(row):
            if not label:
                continue
            img = exemplar if label == "input" else images[label]
            x0, y0 = pad + c * (tile + pad), pad + r * (tile + pad + label_h)
            canvas.paste(
                Image.fromarray((np.clip(img, 0, 1) * 255).round().astype(np.uint8)), (x0, y0 + label_h)
            )
            draw.text((x0, y0 + 2), label + (" (128 px)" if label == "input" else ""), fill=0)
    path = IMG / f"patch-{name}.png"
    canvas.save(path)
    return path


def quality(exs: dict[str, np.ndarray]) -> tuple[dict[str, dict[str, Any]], list[str]]:
    table: dict[str, dict[str, Any]] = {}
    figures = []
    for name, ex in exs.items():
        images, rows = {}, {}
        for label, (method, params) in RUNS.items():
            res = synthesize(method, ex, size=SIZE, params=params, seed=SEED)
            images[label] = res.image
            row: dict[str, Any] = {"copy": res.stats["copy_share"], "energy": gradient_energy(res.image)}
            if "layout" in res.stats:
                row["seam"] = seam_visibility(res.image, res.stats["layout"])["ratio"]
            if label in FIDELITY:
                m = evaluate_pair(ex, res.image, fringes=False)["summary"]
                row["grey_kl"], row["orientation_kl"] = m["grey_kl"], m["orientation_kl"]
            rows[label] = row
        rows["input"] = {"energy": gradient_energy(ex)}
        table[name] = rows
        figures.append(str(figure(name, ex, images).relative_to(ROOT / "docs")))
    return table, figures


def timings(exs: dict[str, np.ndarray]) -> list[tuple[str, str, float, float, str]]:
    ex = exs["gravel"]
    out = []
    cases = [
        ("quilting", QUILT, (256, 256), 3),
        ("gaussian-patch (rclg)", {**GAUSS, "model": "rclg"}, (256, 256), 3),
        ("quilting", QUILT, (2048, 2048), 1),
        ("gaussian-patch (rclg)", {**GAUSS, "model": "rclg"}, (2048, 2048), 1),
        ("random-phase", {}, (2048, 2048), 3),
    ]
    for label, params, size, runs in cases:
        method = label.split(" ")[0]
        synth_times: list[float] = []

        def run(
            method: str = method, params: dict = params, size: tuple = size, sink: list = synth_times
        ) -> None:
            sink.append(synthesize(method, ex, size=size, params=params, seed=SEED).timings["synthesis"])

        total, _ = median_time(run, runs=runs, warmup=1 if size[0] <= 256 else 0)
        load = os.getloadavg()[0]
        out.append((label, f"{size[0]}^2", float(np.median(synth_times[-runs:])), total, f"{load:.1f}"))
    return out


#: What the figures show (looked at for seed 0; the runs are deterministic).
OBSERVATIONS = """## What the figures show

- **brick** (periodic): quilting rebuilds the wall with a few broken joints. LG shows block edges and
  misaligned joints; CLG and RCLG keep most joints continuous across the seams but add dark dashes inside
  the bricks: negative multiples of the light mortar lines, which the linear (Gaussian) model extrapolates
  to, more with CLG than with RCLG. Lighter smears along the top edge: first-row patches are conditioned
  on a left strip only and average mortar lines at several positions. With 2 scales most horizontal
  joints vanish; drawing (`estimate='draw'`) adds speckle to the flat faces and more dark dashes.
- **grass, gravel, soot**: CLG and RCLG lose contrast after the first patch (the top-left one, copied from
  the exemplar). Each patch is the neighbours' mean plus a least-squares fit of the overlap in the
  20-dimensional span of the neighbours; where the overlap (k = 371 values) says little about the rest of
  the patch the fit is weak, the patch falls toward the mean, and the next patch conditions on that. The
  grey-level standard deviation roughly halves (gravel 0.08 vs 0.15, soot 0.07 vs 0.16), hence the large
  grey KL. CLG shows the block grid on grass and gravel (its overlap is kept exactly and the fitted rest
  does not continue it); RCLG's seams are the weakest of all. Drawing from the conditional law instead of
  taking its mode barely helps: with 371 observed values and a rank-20 model the overlap pins the 20
  coefficients, so the conditional law is almost a point.
- LG keeps the contrast but shows block edges, softened by the boundary cut (the paper's Fig. 3 setting).
- **Contrast restored** (bottom row, the default): scaling each new patch's deviations to its neighbours'
  mean spread stops the decay; soot, grass and gravel keep their texture over the whole output.
- **Defaults** (bottom left: N = 5, contrast restored, `estimate='neighbour'`): each patch is one of its
  5 neighbours corrected toward the overlap, the correction fading over the overlap's width, so a brick's
  horizontal joints, which the mean of neighbours with joints at different heights reduces to faint dashes,
  come out whole, and the gravel stones keep their edges. Left: faint dashes inside a few bricks, and a few
  smeared streaks between gravel stones along patch borders.
- Random-phase noise suits the soot (a micro-texture); it cannot make bricks or gravel stones.
"""


def verdict(claim: str, holds: list[str], names: list[str]) -> str:
    """One sentence: where ``claim`` holds and where it does not."""
    fails = [n for n in names if n not in holds]
    if not fails:
        return f"{claim}: holds on every exemplar."
    if not holds:
        return f"{claim}: does **not** hold on any exemplar."
    return f"{claim}: holds on {', '.join(holds)}; does **not** hold on {', '.join(fails)}."


def fmt(v: Any, digits: int = 3) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def main() -> None:
    IMG.mkdir(parents=True, exist_ok=True)
    exs = exemplars()
    start = time.perf_counter()
    table, figures = quality(exs)
    times = timings(exs)
    names = list(exs)
    md = ["# Patch-based synthesis: quilting, locally Gaussian patch models, random-phase noise", ""]
    md += [
        "Written by `python -m benchmarks.bench_patch`. 128 x 128 exemplars, 256 x 256 outputs, seed 0, "
        f"(w, N) = ({W}, {N}) for the Gaussian models (overlap w/4 = 7, sigma = theta = 0.05) and w = {W} "
        "for quilting (overlap w/6 = 5).",
        "",
        "## Figures (like the paper's Figs 2 and 3)",
        "",
        "Top row: input, quilting, then LG, CLG, RCLG pasted without blending (Fig. 2). Middle row: "
        "random-phase noise, quilting with the graph-cut seam, then LG, CLG, RCLG stitched by the boundary "
        "cut (Fig. 3). These are the paper's models literally (`contrast='none'`, `estimate='mean'`). Bottom "
        "row (beyond the paper): the method's defaults with the cut (N = 5, contrast restored, each patch a "
        "neighbour corrected toward the overlap, `estimate='neighbour'`), CLG and RCLG with their contrast "
        "restored (`contrast='restore'`: each new patch keeps its neighbours' spread), RCLG restored and "
        "cut, and RCLG drawn from the conditional law (`estimate='draw'`) with the cut.",
        "",
    ]
    md += [f"![{n}]({f})" for n, f in zip(names, figures, strict=True)]
    head = "| exemplar | " + " | ".join(names) + " |"
    sep = "|---|" + "---|" * len(names)

    def row(label: str, key: str, digits: int = 3) -> str:
        return f"| {label} | " + " | ".join(fmt(table[n][label].get(key), digits) for n in names) + " |"

    md += ["", "## (a) Seam visibility without blending", ""]
    md += [
        "Mean squared grey difference across the patch boundaries (overlap strips) over the interior's; "
        "1 = no visible seam (`synth.evaluate.seam_visibility`). The paper: CLG and RCLG show weaker seams "
        "than LG.",
        "",
        head,
        sep,
    ]
    md += [
        row(label, "seam")
        for label in ("LG", "CLG", "RCLG", "LG + cut", "CLG + cut", "RCLG + cut", "quilting")
    ]
    clg_a = [n for n in names if table[n]["CLG"]["seam"] < table[n]["LG"]["seam"]]
    rclg_a = [n for n in names if table[n]["RCLG"]["seam"] < table[n]["LG"]["seam"]]
    md += ["", verdict("CLG's seams are weaker than LG's", clg_a, names)]
    md += [verdict("RCLG's seams are weaker than LG's", rclg_a, names)]

    md += ["", "## (b) Smoothness: RCLG vs CLG", ""]
    md += [
        "Seam ratio (lower = smoother across seams) and mean squared gradient of the whole output relative "
        "to the exemplar's (below 1 = smoother than the exemplar; the paper: RCLG is smoother, losing fine "
        "detail).",
        "",
        head,
        sep,
        row("CLG", "seam"),
        row("RCLG", "seam"),
        "| CLG gradient / exemplar's | "
        + " | ".join(fmt(table[n]["CLG"]["energy"] / table[n]["input"]["energy"]) for n in names)
        + " |",
        "| RCLG gradient / exemplar's | "
        + " | ".join(fmt(table[n]["RCLG"]["energy"] / table[n]["input"]["energy"]) for n in names)
        + " |",
        "| LG gradient / exemplar's | "
        + " | ".join(fmt(table[n]["LG"]["energy"] / table[n]["input"]["energy"]) for n in names)
        + " |",
    ]
    smoother = [n for n in names if table[n]["RCLG"]["seam"] < table[n]["CLG"]["seam"]]
    md += ["", verdict("RCLG's seams are weaker than CLG's", smoother, names)]
    flatter = [n for n in names if table[n]["RCLG"]["energy"] < table[n]["LG"]["energy"]]
    md += [verdict("RCLG's output is smoother than LG's (the paper's 'smoother result')", flatter, names)]
    md += ["", "## (c) Verbatim copies: RCLG vs quilting at the same patch size", ""]
    md += [
        f"Share of output pixels whose 7 x 7 patch is within RMS {COPY_THRESHOLD} of an exemplar patch "
        "(`synth.evaluate.copy_map`).",
        "",
        head,
        sep,
    ] + [row(label, "copy") for label in ("quilting", "LG", "CLG", "RCLG", "RCLG + cut", "random phase")]
    fewer = [n for n in names if table[n]["RCLG"]["copy"] < table[n]["quilting"]["copy"]]
    md += ["", verdict("RCLG copies less than quilting", fewer, names)]
    md += [
        "On brick the flat brick faces match flat exemplar patches whatever the method, which inflates every "
        "share there; the soot, gravel and grass shares are the informative ones."
    ]
    md += ["", "## Fidelity (grey / orientation KL to the exemplar; targets < 0.05 / < 0.10)", "", head, sep]
    for label in FIDELITY:
        md.append(row(label, "grey_kl"))
        md[-1] = md[-1].replace(f"| {label} |", f"| {label}: grey KL |", 1)
        md.append(row(label, "orientation_kl"))
        md[-1] = md[-1].replace(f"| {label} |", f"| {label}: orientation KL |", 1)
    good = [
        n
        for n in names
        if table[n]["RCLG + cut"]["grey_kl"] < 0.05 and table[n]["RCLG + cut"]["orientation_kl"] < 0.10
    ]
    md += ["", verdict("rclg + boundary-cut (the paper's) meets both targets", good, names)]
    restored = [
        n
        for n in names
        if table[n]["RCLG + cut, restored"]["grey_kl"] < 0.05
        and table[n]["RCLG + cut, restored"]["orientation_kl"] < 0.10
    ]
    md += [verdict("rclg + boundary-cut with contrast restored (N = 20) meets both targets", restored, names)]
    for label, claim in (
        (
            "RCLG + cut, N = 5, mean",
            "rclg + boundary-cut with N = 5 and the mean estimate meets both targets",
        ),
        (
            "RCLG + cut, defaults (N = 5, neighbour)",
            "rclg + boundary-cut with the defaults (N = 5, estimate='neighbour') meets both targets",
        ),
    ):
        meets = [
            n for n in names if table[n][label]["grey_kl"] < 0.05 and table[n][label]["orientation_kl"] < 0.10
        ]
        md += [verdict(claim, meets, names)]
    better = [
        n
        for n in names
        if table[n]["RCLG + cut, 2 scales"]["grey_kl"] < table[n]["RCLG + cut"]["grey_kl"]
        and table[n]["RCLG + cut, 2 scales"]["orientation_kl"] < table[n]["RCLG + cut"]["orientation_kl"]
    ]
    md += [verdict("2 scales improve both KLs over 1 scale", better, names)]
    drawn = [n for n in names if table[n]["RCLG draw + cut"]["grey_kl"] < table[n]["RCLG + cut"]["grey_kl"]]
    md += [verdict("drawing instead of the mean lowers the grey KL", drawn, names)]
    md += ["", "## Times", ""]
    md += [
        "From the 128 x 128 gravel exemplar; median of runs (256^2: 3 runs after a warm-up; 2048^2 Gaussian "
        "and quilting: one run). `synthesis` excludes the verbatim-copy map that every result carries; "
        "`total` includes it. Load = 1-minute load average of the shared 2-core machine after the case.",
        "",
        "| method | output | synthesis (s) | total (s) | load |",
        "|---|---|---|---|---|",
    ]
    md += [f"| {m} | {s} | {a:.2f} | {b:.2f} | {ld} |" for m, s, a, b, ld in times]
    md += ["", OBSERVATIONS]
    md += ["", f"_Benchmark wall time {time.perf_counter() - start:.0f} s._", ""]
    DOC.write_text("\n".join(md))
    write_section(
        "patch",
        "## Patch family (quilting, LG/CLG/RCLG, random phase)\n\nSee docs/patch.md.\n\n"
        "| method | output | synthesis (s) | total (s) | load |\n|---|---|---|---|---|\n"
        + "\n".join(f"| {m} | {s} | {a:.2f} | {b:.2f} | {ld} |" for m, s, a, b, ld in times),
    )
    print(DOC.read_text())


if __name__ == "__main__":
    main()
