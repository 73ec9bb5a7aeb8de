"""The 2D methods' quality, side by side with the best open peer (issue 13).

Run: ``python -m benchmarks.bench_quality`` (writes docs/quality.md and docs/img/quality-*.png; the sections
other benchmarks own there, between ``<!-- begin:name -->`` and ``<!-- end:name -->``, are kept).
``--seeds 1`` for a quick look. ``--methods quilting,gaussian-patch`` re-measures only those methods and
replaces only their rows in docs/quality.md and their panels (the first seed) in the pictures; the other
rows and panels stay as they are.

Every 2D method with its defaults, 128 x 128 exemplars -> 256 x 256, seeds 1-3, on the public crops
(``skimage.data`` grass, gravel, brick: ``[:128, :128]``, grey), HRTEM soot (``hrtem-soot-128.png``), a
generated bent-laminae exemplar and a generated wood-grain exemplar (long wavy fibres with their own grey
levels, :func:`texsynth.synth.io.patterns.wood_grain`). Measures
(:func:`texsynth.synth.evaluate.evaluate_pair` unless said):

- grey-level KL and orientation KL against the exemplar (lower is better);
- coherence ratio: the output's mean structure-tensor coherence over the exemplar's (1 = as oriented);
- strand-length ratio: the output's mean fringe (strand) length over the exemplar's (the study's fringe
  extraction; 1 = strands as long, below 1 = broken strands). The strands are each exemplar's thin lines:
  dark ones (``polarity='dark'``, the HRTEM fringes' convention) except brick's, whose lines are its bright
  mortar joints (:data:`STRAND_POLARITY`; the dark polarity finds 3 strands in the brick exemplar, a ratio
  of means over 3 samples, the bright one 16);
- seam: for methods that report where each pixel came from (``source_map``: the pixel methods and
  quilting), :func:`texsynth.synth.evaluate.patches.seam_contrast` (gradient energy across source seams over
  that across coherent edges; 1 = seams as the texture itself); for the Gaussian patch models and
  feature-guided, :func:`texsynth.synth.evaluate.seam_visibility` of their patch layout; none for random
  phase.

The peer column is Embark's texture-synthesis 0.8 (``generate --out-size 256``) on the same crops, its
outputs in ../shared/data/peers/ (grass, gravel, brick, soot); the same measures are computed on them.
Cells are the mean over seeds, with the worst seed in brackets.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from skimage import data as skdata

from benchmarks._report import DATA
from texsynth.synth.api import synthesize
from texsynth.synth.evaluate import evaluate_pair, seam_contrast, seam_visibility
from texsynth.synth.evaluate.breaks import seams_from_sources
from texsynth.synth.io import load_image, save_image
from texsynth.synth.io.patterns import undulating_laminae, wood_grain

DOCS = Path(__file__).resolve().parent.parent / "docs"
PEERS = DATA / "peers"
SIZE = (256, 256)
METHODS = ("wei-levoy", "tensor-constrained", "quilting", "gaussian-patch", "feature-guided", "random-phase")
#: Targets of issue 13 for ``tensor-constrained`` and the default unconstrained method (``wei-levoy``).
TARGETS = {"grey_kl": 0.05, "orientation_kl": 0.10, "strand_ratio": 0.8, "seam": 1.2}
#: Exemplars whose strands are bright lines (the rest: dark, the fringe extraction's default).
STRAND_POLARITY = {"brick": "bright"}
MEASURES = (
    ("grey_kl", "grey KL"),
    ("orientation_kl", "orient. KL"),
    ("coherence_ratio", "coherence ratio"),
    ("strand_ratio", "strand ratio"),
    ("seam", "seam"),
)


def exemplars() -> dict[str, np.ndarray]:
    """The six exemplars, 128 x 128 grey in [0, 1]."""
    out: dict[str, np.ndarray] = {}
    for name in ("grass", "gravel", "brick"):
        img = getattr(skdata, name)()[:128, :128]
        out[name] = (img if img.ndim == 2 else img.mean(axis=2)).astype(np.float32) / 255.0
    soot = DATA / "hrtem-soot-128.png"
    if soot.exists():
        out["hrtem-soot-128"] = load_image(soot)
    out["laminae-bent-128"] = undulating_laminae((128, 128), 7, 16, 128, noise=0.3)
    out["wood-grain-128"] = wood_grain((128, 128), seed=1)
    return out


def peer_output(name: str) -> np.ndarray | None:
    path = PEERS / f"embark-{name}-256.png"
    if not path.exists():
        return None
    img = load_image(path)
    return img if img.ndim == 2 else img.mean(axis=2).astype(np.float32)


def measures(
    exemplar: np.ndarray, image: np.ndarray, result: Any = None, *, polarity: str = "dark"
) -> dict[str, float | None]:
    """The five measures of one output (``result``: its :class:`texsynth.synth.api.Result`, for the seams;
    ``polarity``: the strands' polarity, :data:`STRAND_POLARITY`)."""
    m = evaluate_pair(exemplar, image, fringe_options={"polarity": polarity})
    coh = m["structure"]["coherence_mean"]
    fr = m.get("fringes", {})
    strand = None
    if fr and fr.get("exemplar", {}).get("mean_length") and fr.get("output", {}).get("mean_length"):
        strand = fr["output"]["mean_length"] / fr["exemplar"]["mean_length"]
    seam = None
    if result is not None and "source_map" in result.extras:
        seam = seam_contrast(image, seams_from_sources(result.extras["source_map"]))["ratio"]
    elif result is not None and "layout" in result.stats:
        seam = seam_visibility(image, result.stats["layout"])["ratio"]
    return {
        "grey_kl": m["grey"]["kl"],
        "orientation_kl": m["structure"]["orientation_kl"],
        "coherence_ratio": coh["output"] / max(coh["exemplar"], 1e-12),
        "strand_ratio": strand,
        "seam": seam if seam is None or np.isfinite(seam) else None,
    }


def _worst(key: str, values: list[float]) -> float:
    """The worst of a measure's values: the largest KL or seam; the farthest ratio from 1."""
    if key in ("coherence_ratio", "strand_ratio"):
        return min(values, key=lambda v: -abs(v - 1.0))
    return max(values)


def cell(key: str, runs: list[dict[str, float | None]]) -> str:
    values = [r[key] for r in runs if r[key] is not None]
    if not values:
        return "-"
    if len(values) == 1:
        return f"{values[0]:.3f}"
    return f"{statistics.mean(values):.3f} ({_worst(key, values):.3f})"


def meets(key: str, runs: list[dict[str, float | None]]) -> bool:
    values = [r[key] for r in runs if r[key] is not None]
    if not values or key not in TARGETS:
        return True
    if key == "strand_ratio":
        return min(values) > TARGETS[key]
    return max(values) < TARGETS[key] if key != "seam" else max(values) <= TARGETS[key]


def figure(exemplar: np.ndarray, outputs: list[np.ndarray]) -> np.ndarray:
    """The exemplar (top left of a 256 tile) then each output, 4 px white gutters."""
    tiles = []
    ex_tile = np.ones(SIZE, np.float32)
    ex_tile[: exemplar.shape[0], : exemplar.shape[1]] = exemplar
    for img in [ex_tile, *outputs]:
        tiles += [img.astype(np.float32), np.ones((SIZE[0], 4), np.float32)]
    return np.concatenate(tiles[:-1], axis=1)


def replace_panels(path: Path, panels: dict[str, np.ndarray]) -> None:
    """Replace the panels of some methods (name -> output) in one of :func:`figure`'s pictures."""
    if not path.exists() or not panels:
        return
    picture = load_image(path)
    picture = picture if picture.ndim == 2 else picture.mean(axis=2).astype(np.float32)
    for method, image in panels.items():
        x = (1 + METHODS.index(method)) * (SIZE[1] + 4)  # the exemplar's tile first, then METHODS' order
        picture[: SIZE[0], x : x + SIZE[1]] = image
    save_image(path, picture)


def replace_rows(methods: tuple[str, ...], n_seeds: int) -> int:
    """Re-measure ``methods`` on every exemplar and replace their rows in docs/quality.md's tables."""
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise SystemExit(f"--methods: unknown {unknown}; choose among {', '.join(METHODS)}")
    doc = DOCS / "quality.md"
    text = doc.read_text()
    seeds = tuple(range(1, n_seeds + 1))
    for name, exemplar in exemplars().items():
        polarity = STRAND_POLARITY.get(name, "dark")
        start = text.find(f"## {name}\n")
        end = text.find("\n## ", start + 1)
        if start < 0:
            print(f"{name}: no section in {doc.name}, skipped", flush=True)
            continue
        section = text[start:end]
        panels: dict[str, np.ndarray] = {}
        for method in methods:
            runs, times = [], []
            for seed in seeds:
                t0 = time.perf_counter()
                result = synthesize(method, exemplar, size=SIZE, seed=seed)
                times.append(time.perf_counter() - t0)
                runs.append(measures(exemplar, result.image, result, polarity=polarity))
                if seed == seeds[0]:
                    panels[method] = result.image
            cells = " | ".join(cell(key, runs) for key, _ in MEASURES)
            row = f"| `{method}` | {statistics.median(times):.1f} | {cells} |"
            section = re.sub(rf"^\| `{re.escape(method)}` \|.*$", row, section, count=1, flags=re.M)
            print(f"{name}: {row}", flush=True)
        text = text[:start] + section + text[end:]
        replace_panels(DOCS / "img" / f"quality-{name}.png", panels)
    note = (
        f"<!-- rows-note -->_Rows of {', '.join(f'`{m}`' for m in methods)} re-measured alone "
        f"(`--methods`, {time.strftime('%Y-%m-%d')}, 1-minute load {os.getloadavg()[0]:.1f} after them on "
        "the shared 2-core machine): their time column is wall time under that load; their panels in the "
        f"pictures replaced (seed {seeds[0]})._\n\n"
    )
    text = re.sub(r"<!-- rows-note -->.*?\n\n", "", text, flags=re.S)
    first = text.find("\n## ") + 1
    doc.write_text(text[:first] + note + text[first:])
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="the 2D quality table (docs/quality.md)")
    parser.add_argument("--seeds", type=int, default=3, help="seeds 1..N (default 3)")
    parser.add_argument(
        "--methods", default="", help="comma-separated subset: replace only these methods' rows in the doc"
    )
    args = parser.parse_args(argv)
    if args.methods:
        return replace_rows(tuple(m.strip() for m in args.methods.split(",") if m.strip()), args.seeds)
    seeds = tuple(range(1, args.seeds + 1))
    (DOCS / "img").mkdir(parents=True, exist_ok=True)
    head = "| method | time (s) | " + " | ".join(label for _, label in MEASURES) + " |"
    sep = "|" + "---|" * (2 + len(MEASURES))
    sections = [
        "# Quality of the 2D methods against the best open peer\n\n"
        "Generated by `python -m benchmarks.bench_quality` (its docstring defines every measure). "
        f"128 x 128 exemplars -> 256 x 256, every method with its defaults, seeds {seeds[0]}-{seeds[-1]}; "
        "cells: mean over seeds (worst seed). Targets (issue 13) for `tensor-constrained` and the default "
        "unconstrained method `wei-levoy`: grey KL < 0.05, orientation KL < 0.10, strand ratio > 0.8, "
        "seam <= 1.2. Strands are dark lines, brick's its bright mortar joints. The peer is Embark "
        "texture-synthesis 0.8 (one output per exemplar)."
    ]
    verdicts: dict[str, list[str]] = {m: [] for m in ("wei-levoy", "tensor-constrained")}
    started = time.perf_counter()
    for name, exemplar in exemplars().items():
        lines = [head, sep]
        pictures = []
        polarity = STRAND_POLARITY.get(name, "dark")
        for method in METHODS:
            runs, times = [], []
            for seed in seeds:
                t0 = time.perf_counter()
                result = synthesize(method, exemplar, size=SIZE, seed=seed)
                times.append(time.perf_counter() - t0)
                runs.append(measures(exemplar, result.image, result, polarity=polarity))
                if seed == seeds[0]:
                    pictures.append(result.image)
            print(f"{name} {method}: {statistics.median(times):.1f} s", flush=True)
            cells = " | ".join(cell(key, runs) for key, _ in MEASURES)
            lines.append(f"| `{method}` | {statistics.median(times):.1f} | {cells} |")
            if method in verdicts:
                missed = [label for key, label in MEASURES if not meets(key, runs)]
                verdicts[method].append(
                    f"{name}: " + ("all met" if not missed else "missed " + ", ".join(missed))
                )
        peer = peer_output(name)
        if peer is not None:
            peer_runs = [measures(exemplar, peer, polarity=polarity)]
            cells = " | ".join(cell(key, peer_runs) for key, _ in MEASURES)
            lines.append(f"| peer (Embark) | - | {cells} |")
            pictures.append(peer)
        save_image(DOCS / "img" / f"quality-{name}.png", figure(exemplar, pictures))
        order = ", ".join([*METHODS, *(["peer"] if peer is not None else [])])
        sections.append(
            f"## {name}\n\n" + "\n".join(lines) + f"\n\nExemplar, then seed {seeds[0]} of: {order}.\n\n"
            f"![{name}](img/quality-{name}.png)\n"
        )
    summary = ["## Targets\n"]
    for method, notes in verdicts.items():
        summary.append(f"- `{method}`: " + "; ".join(notes) + ".")
    sections.append("\n".join(summary) + "\n")
    sections.append(f"_Benchmark wall time {time.perf_counter() - started:.0f} s (2 cores, shared)._\n")
    # sections other benchmarks own (<!-- begin:name --> ... <!-- end:name -->, e.g. bench_tileable's) stay
    doc = DOCS / "quality.md"
    old = doc.read_text() if doc.exists() else ""
    blocks = [m.group(0) for m in re.finditer(r"<!-- begin:(.*?) -->.*?<!-- end:\1 -->", old, re.S)]
    doc.write_text("\n\n".join([*sections, *blocks]) + ("\n" if blocks else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
