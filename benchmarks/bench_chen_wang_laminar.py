"""`solid-chen-wang` against the laminar known answers and the real onion crops (issue 24's table).

Run: ``python -m benchmarks.bench_chen_wang_laminar [--only KEY] [--seeds N | --seeds 2,3] [--report]``;
results go to docs/chen-wang-laminar.json (rows kept between runs, per seed), the table is printed for
docs/solid.md and the seed-1 mid-slices and cube to docs/img/laminar-cw-*.png.

Rows: the known answers of :mod:`benchmarks.bench_laminar` (onions and the turbostratic stack, one exemplar,
128^2 mid-slice of the 128^3 truth) at 64^3 and 128^3, the defaults and the paper's literal settings
(:data:`CHEN_WANG_PAPER`), measured against the truth's slices of the same size
(:func:`texsynth.synth.evaluate.truth.evaluate_against_truth`); the real crops
``benchmarks/data/hrtem-onion*-128.png`` against the exemplar
(:func:`texsynth.synth.evaluate.evaluate_volume`, every second slice); and the departures measured against
their misses (``solve_radius``, ``position_weight``; none a default) and the sheet length's candidates
(``structure_length``: 4 periods, the default before session cw5; 3; 2.5; solid-kopf's fit) and the shells
around random centres (``shells='centres'``, session cw6; their spacing fitted and ``shells='auto'``, cw8).
Cells as in docs/laminar.md: ``xy / xz / yz`` means over the seeds, the worst seed-axis value in brackets,
**x** when it misses its target; CPU s the median process CPU time of
:func:`texsynth.synth.api.synthesize` (both cores).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.bench_laminar import (
    CHEN_WANG_PAPER,
    _cells,
    _head,
    _save,
    against_exemplars,
    exemplars,
    truths,
)
from texsynth.synth.api import synthesize
from texsynth.synth.evaluate.truth import evaluate_against_truth, truth_slices
from texsynth.synth.io import load_image
from texsynth.synth.pixel.laminar import fitted_structure_length

DOCS = Path(__file__).resolve().parent.parent / "docs"
DATA = Path(__file__).resolve().parent / "data"
RESULTS = DOCS / "chen-wang-laminar.json"
#: (family, label, params, side)
RUNS: tuple[tuple[str, str, dict[str, Any], int], ...] = (
    ("onions", "defaults", {}, 64),
    ("turbostratic", "defaults", {}, 64),
    ("turbostratic", "structure=none", {"structure": "none"}, 64),
    ("onions", "paper", CHEN_WANG_PAPER, 64),
    ("turbostratic", "paper", CHEN_WANG_PAPER, 64),
    ("onions", "defaults", {}, 128),
    ("turbostratic", "defaults", {}, 128),
    ("onions", "paper", CHEN_WANG_PAPER, 128),
    ("turbostratic", "paper", CHEN_WANG_PAPER, 128),
    ("onion crop", "defaults", {}, 64),
    ("onion crop", "grey_remap=False", {"grey_remap": False}, 64),
    ("onion-core crop", "defaults", {}, 64),
    ("onion-core crop", "grey_remap=False", {"grey_remap": False}, 64),
    # Departures measured against the misses (docs/solid.md, session cw4); none is a default.
    ("onions", "solve_radius=1", {"solve_radius": 1}, 64),
    ("onions", "structure_length=2", {"structure_length": 2.0}, 64),
    ("onions", "structure_length=3", {"structure_length": 3.0}, 64),
    ("onions", "structure_length=3", {"structure_length": 3.0}, 128),
    ("onion crop", "solve_radius=1", {"solve_radius": 1}, 64),
    ("onion crop", "position_weight=1", {"position_weight": 1.0}, 64),
    ("onion-core crop", "solve_radius=1", {"solve_radius": 1}, 64),
    ("onion-core crop", "position_weight=1", {"position_weight": 1.0}, 64),
    # The sheet length's candidates (session cw5): 4 periods (the default before), fixed 3 (the onions'
    # default since: kopf's fit 2.1 kept within 3-4), solid-kopf's fit (the crops: 4.4-4.7; default 4).
    ("onions", "structure_length=4", {"structure_length": 4.0}, 64),
    ("onions", "structure_length=4", {"structure_length": 4.0}, 128),
    ("onions", "structure_length=fitted", {"structure_length": "fitted"}, 64),
    ("onions", "structure_length=fitted", {"structure_length": "fitted"}, 128),
    ("onion crop", "structure_length=3", {"structure_length": 3.0}, 64),
    ("onion crop", "structure_length=fitted", {"structure_length": "fitted"}, 64),
    ("onion-core crop", "structure_length=3", {"structure_length": 3.0}, 64),
    ("onion-core crop", "structure_length=fitted", {"structure_length": "fitted"}, 64),
    # Session cw6: the onions' last 64^3 misses. Shells around random centres (opt-in, not a default: the
    # crops do not gain) and a shorter sheet (2.5 periods: fewer closed shells); docs/solid.md.
    # Their spacing then: 1.5 sheet lengths (4.5 periods on the onions, 6 on the crops), the same bytes.
    ("onions", "shells=centres-1.5-lengths", {"shells": "centres", "centre_spacing": 4.5}, 64),
    ("onions", "shells=centres-1.5-lengths", {"shells": "centres", "centre_spacing": 4.5}, 128),
    ("onion crop", "shells=centres-1.5-lengths", {"shells": "centres", "centre_spacing": 6.0}, 64),
    ("onion-core crop", "shells=centres-1.5-lengths", {"shells": "centres", "centre_spacing": 6.0}, 64),
    ("onions", "structure_length=2.5", {"structure_length": 2.5}, 64),
    # Session cw8: the centres' spacing fitted to the fringes' curvature, and shells='auto' (the default
    # since: the centres where the fringes' centres of curvature gather, the onion truth; the surfaces on
    # the crops, whose rows keep their bytes); the surfaces' rows are the defaults' before.
    ("onions", "shells=surfaces", {"shells": "surfaces"}, 64),
    ("onions", "shells=surfaces", {"shells": "surfaces"}, 128),
    ("onion crop", "shells=centres-fitted", {"shells": "centres"}, 64),
    ("onion-core crop", "shells=centres-fitted", {"shells": "centres"}, 64),
    # Session 17: shells='auto' takes the fitted centres also where one centre explains the fringes'
    # orientations (a particle seen whole: both crops); their surfaces, the defaults' before, measured beside.
    ("onion crop", "shells=surfaces", {"shells": "surfaces"}, 64),
    ("onion-core crop", "shells=surfaces", {"shells": "surfaces"}, 64),
)


def _resolved(params: dict[str, Any], image: np.ndarray) -> dict[str, Any]:
    """``params`` with ``structure_length='fitted'`` replaced by solid-kopf's fit to ``image`` (periods),
    and ``'fitted>=3'`` by that fit, at least 3: candidates measured as numbers (a default's bytes)."""
    length = params.get("structure_length")
    if length not in ("fitted", "fitted>=3"):
        return params
    fit = fitted_structure_length([image])
    return {**params, "structure_length": max(fit, 3.0) if length == "fitted>=3" else fit}


def _seeds(text: str) -> list[int]:
    """``'3'``: seeds 1-3; ``'2,3'``: those seeds."""
    return [int(t) for t in text.split(",")] if "," in text else list(range(1, int(text) + 1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="solid-chen-wang on laminar known answers and real crops")
    parser.add_argument("--only", action="append", default=[], help="run the rows whose key contains this")
    parser.add_argument("--seeds", default="3", help="N: seeds 1..N (default 3); or a list, 2,3")
    parser.add_argument("--report", action="store_true", help="only print the table from the results")
    args = parser.parse_args(argv)
    saved: dict[str, Any] = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    if not args.report:
        known = truths()
        for family, label, params, side in RUNS:
            key = f"{family}, `solid-chen-wang` {label}, {side}^3"
            if args.only and not any(o in key for o in args.only):
                continue
            if family in known:
                planes = exemplars(known[family], "one")
                ref = truth_slices(known[family], (side,) * 3)
            else:
                image = np.ascontiguousarray(load_image(DATA / f"hrtem-{family.split()[0]}-128.png"))
                planes = dict.fromkeys(("xy", "xz", "yz"), image)
            rows = []
            for seed in _seeds(args.seeds):
                cpu, wall = time.process_time(), time.perf_counter()
                result = synthesize(
                    "solid-chen-wang",
                    exemplars=planes,
                    size=(side,) * 3,
                    params=_resolved(params, planes["xy"]),
                    seed=seed,
                )
                cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
                if family in known:
                    axes = _head(evaluate_against_truth(ref, result.image)["summary"])
                else:
                    axes = against_exemplars(planes["xy"], result.image)
                length = result.stats.get("start_length")
                rows.append({"seed": seed, "cpu": cpu, "wall": wall, "axes": axes, "start_length": length})
                print(f"{key} seed {seed}: {cpu:.1f} s CPU, {wall:.1f} s wall", flush=True)
                if seed == 1:
                    name = f"cw-{family.replace(' ', '-')}-{label.replace('=', '-')}-{side}"
                    _save(name, result.image, planes, f"solid-chen-wang {label} {side}^3, seed 1")
            # Re-read before writing: other runs of this script may have saved their rows meanwhile.
            saved = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
            # Rows of other seeds stay (rows saved before session cw5 carry no seed: 1, 2, ... in order).
            kept = {r.get("seed", i + 1): r for i, r in enumerate(saved.get(key, []))}
            kept.update({r["seed"]: r for r in rows})
            saved[key] = [kept[s] for s in sorted(kept)]
            RESULTS.write_text(json.dumps(saved, indent=1) + "\n")
    print(table(saved))
    return 0


def table(saved: dict[str, Any]) -> str:
    """The markdown table of every saved row (the measures of docs/laminar.md, CPU median over seeds)."""
    head = "| run | seeds | coherence ratio | orient. KL | length KS | tortuosity KS | grey KL | contrast "
    head += "| CPU s |"
    lines = [head, "|---|---|---|---|---|---|---|---|---|"]
    for key, rows in saved.items():
        cpu = statistics.median(r["cpu"] for r in rows)
        lines.append(f"| {key} | {len(rows)} | " + " | ".join(_cells(rows)) + f" | {cpu:.1f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
