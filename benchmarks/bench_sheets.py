"""Which starting sheets fit a real laminar crop: surfaces, or straight stacks in domains (issue 24).

Run: ``python -m benchmarks.bench_sheets`` (writes docs/sheets-crops.json, the section ``sheets-crops``
of docs/solid.md and docs/img/sheets-*.png); ``--report`` rewrites the section from the JSON alone;
``--only METHOD`` runs that method's rows and keeps the others'; ``--shifts`` only prints the choice of
``shells='sheets'`` on every crop moved by up to 16 px over the whole image (the measure alone).

The real crops whose single exemplar takes the laminar start (the onion crops of benchmarks/data,
../shared/data's soot-256, two windows of the onion crop moved nearer its core, :data:`SHIFTED`). For each:
what the exemplar measures (:func:`bend_length`, how far its fringes keep their orientation; the centres of
curvature; one centre's share) and what ``shells='sheets'`` and ``'auto'`` choose; then ``solid-kopf`` 64^3
with its default (the start and the domains' spacing it takes are in the row's name), the surfaces and
domains 2, 2.5 and 3 periods apart, and ``solid-chen-wang`` with its default and each of the two other
starts (centres, domains, surfaces). Seeds 1-3; per axis every second slice against the exemplar
(``bench_laminar.against_exemplars``): cells ``xy / xz / yz`` means over the seeds and the worst seed-axis,
the targets of docs/solid.md. Pictures: seed 1's mid-slices of the surfaces and of the default domains (the
domains 2.5 periods apart where the default is the surfaces), for each crop.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from benchmarks._report import DATA, machine, write_section
from benchmarks.bench_laminar import DOCS, MEASURES, _cells, against_exemplars
from texsynth.synth.api import synthesize
from texsynth.synth.io import load_image
from texsynth.synth.output.volume import slices_image
from texsynth.synth.pixel import laminar

RESULTS = DOCS / "sheets-crops.json"
CROPS = {
    "onion": DOCS.parent / "benchmarks" / "data" / "hrtem-onion-128.png",
    "onion top": DOCS.parent / "benchmarks" / "data" / "hrtem-onion-top-128.png",
    "onion core": DOCS.parent / "benchmarks" / "data" / "hrtem-onion-core-128.png",
    "particle edge": DOCS.parent / "benchmarks" / "data" / "hrtem-particle-edge-128.png",
    "soot-256": DATA / "hrtem-soot-256.png",
}
#: The image the crops are windows of, and each crop's window there (row, column, side).
SOURCE = DOCS.parent / "benchmarks" / "data" / "hrtem-fringe-mapping-512.png"
WINDOWS = {
    "onion": (120, 300, 128),
    "onion top": (75, 280, 128),
    "onion core": (92, 296, 128),
    "particle edge": (384, 128, 128),
    "soot-256": (256, 256, 256),
}
SHIFTS = (-16, -8, 0, 8, 16)
#: Crops moved over :data:`SOURCE` that the runs add (rows, columns of px): the onion crop nearer its core.
SHIFTED = {"onion, 16 px up": ("onion", -16, 0), "onion, 8 px up": ("onion", -8, 0)}
SIDE = 64
SEEDS = (1, 2, 3)
KOPF_RUNS = {
    "surfaces": {"shells": "surfaces"},
    **{f"domains {d:g}": {"shells": "domains", "centre_spacing": d} for d in (2.0, 2.5, 3.0)},
}
#: The row of the domains :data:`DOMAIN_SPACING` apart (pictured where the default is the surfaces).
KOPF_DOMAINS = f"domains {laminar.DOMAIN_SPACING:g}"


def measures(image: np.ndarray) -> dict[str, Any]:
    """What the exemplar measures, and what the two automatic choices take."""
    sheets = laminar.choose_shells("sheets", None, [image])
    auto = laminar.choose_shells("auto", None, [image])
    return {
        "bend": sheets.bend,
        "concentration": sheets.concentration,
        "concentric": auto.concentric,
        "sheets": sheets.kind,
        "auto": auto.kind,
    }


def _run(method: str, image: np.ndarray, params: dict[str, Any], seed: int) -> dict[str, Any]:
    planes = dict.fromkeys(("xy", "xz", "yz"), image)
    cpu, wall = time.process_time(), time.perf_counter()
    result = synthesize(method, exemplars=planes, size=(SIDE,) * 3, params=params, seed=seed)
    cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
    return {
        "seed": seed,
        "cpu": cpu,
        "wall": wall,
        "shells": result.stats.get("shells"),
        "spacing": result.stats.get("centre_spacing"),
        "axes": against_exemplars(image, result.image),
        "volume": result.image,
    }


def run(only: tuple[str, ...] = ()) -> dict[str, Any]:
    """Every crop's runs; with ``only``, just those methods' (the others' rows kept from the JSON)."""
    saved = json.loads(RESULTS.read_text())["crops"] if only and RESULTS.exists() else {}
    out: dict[str, Any] = {"machine": machine(), "crops": {}}
    source = np.ascontiguousarray(load_image(SOURCE, mode="grey"), dtype=np.float32)
    for name in [*CROPS, *SHIFTED]:
        if name in CROPS:
            path = CROPS[name]
            image = np.ascontiguousarray(load_image(path, mode="grey"), dtype=np.float32)
            where = {"file": path.name, "stem": path.stem}
        else:
            base, dr, dc = SHIFTED[name]
            image, (r, c, side) = _window(source, base, dr, dc)
            window = f"rows {r}-{r + side - 1}, columns {c}-{c + side - 1}"
            where = {"file": f"{SOURCE.name}, {window}", "stem": f"{CROPS[base].stem}-{-dr}up"}
        crop: dict[str, Any] = {**where, **measures(image), "rows": {}}
        runs = [("solid-kopf", "default", {})]
        runs += [("solid-kopf", key, params) for key, params in KOPF_RUNS.items()]
        runs.append(("solid-chen-wang", "default", {}))
        others = [kind for kind in ("centres", "domains", "surfaces") if kind != crop["auto"]]
        runs += [("solid-chen-wang", kind, {"shells": kind}) for kind in others]  # every other start
        kept = saved.get(name, {}).get("rows", {})
        for method, key, params in runs:
            if only and method not in only and f"{method} {key}" in kept:
                crop["rows"][f"{method} {key}"] = kept[f"{method} {key}"]
                continue
            rows = [_run(method, image, params, seed) for seed in SEEDS]
            domains_row = "default" if crop["sheets"] == "domains" else KOPF_DOMAINS
            if method == "solid-kopf" and key in ("surfaces", domains_row):
                slug = f"sheets-{crop['stem']}-{'surfaces' if key == 'surfaces' else 'domains'}"
                title = f"{name}, solid-kopf {key}, {SIDE}^3, seed {SEEDS[0]}"
                Image.fromarray(slices_image(rows[0]["volume"], image, title=title)).save(
                    DOCS / "img" / f"{slug}.png"
                )
            for row in rows:
                del row["volume"]
            crop["rows"][f"{method} {key}"] = rows
            print(f"{name}: {method} {key} done", flush=True)
        out["crops"][name] = crop
    RESULTS.write_text(json.dumps(out, indent=1) + "\n")
    return out


def _window(source: np.ndarray, name: str, dr: int, dc: int) -> tuple[np.ndarray, tuple[int, int, int]]:
    """Crop ``name``'s window of ``source`` moved by ``dr``, ``dc`` px, and where it lies (row, column,
    side); an empty image where it leaves ``source``."""
    row, col, side = WINDOWS[name]
    r, c = row + dr, col + dc
    if r < 0 or c < 0 or r + side > source.shape[0] or c + side > source.shape[1]:
        return np.empty((0, 0), dtype=source.dtype), (r, c, side)
    return np.ascontiguousarray(source[r : r + side, c : c + side]), (r, c, side)


def shifts() -> str:
    """Each crop moved by :data:`SHIFTS` px in rows and columns over :data:`SOURCE` (inside it): which
    start one exemplar gets (``'auto'`` structure, the pilot taken as laminar) and the range of the bend."""
    image = np.ascontiguousarray(load_image(SOURCE, mode="grey"), dtype=np.float32)
    planes = ("xy", "xz", "yz")
    lines = [
        "| crop | positions | domains | surfaces | random start | bend (periods) |",
        "|---|---|---|---|---|---|",
    ]
    for name in WINDOWS:
        kinds, bends = [], []
        for dr in SHIFTS:
            for dc in SHIFTS:
                crop, _ = _window(image, name, dr, dc)
                if crop.size == 0:
                    continue
                if not laminar.starts_laminar(
                    "auto", dict.fromkeys(planes, crop), planes, True, lambda _: True
                ):
                    kinds.append("random")
                    continue
                chosen = laminar.choose_shells("sheets", None, [crop])
                kinds.append(chosen.kind)
                bends.append(chosen.bend)
        counts = [kinds.count(k) for k in ("domains", "surfaces", "random")]
        spread = f"{min(bends):.2f}-{max(bends):.2f} (median {np.median(bends):.2f})" if bends else "n/a"
        lines.append(f"| {name} | {len(kinds)} | " + " | ".join(map(str, counts)) + f" | {spread} |")
    return "\n".join(lines)


def _label(key: str, rows: list[dict[str, Any]]) -> str:
    """A default row's name with the start it took (and the domains' spacing)."""
    if not key.endswith("default"):
        return key
    shells, spacing = rows[0]["shells"], rows[0].get("spacing")
    start = f"{shells} {spacing:.2g}" if shells == "domains" and spacing else shells
    return f"{key} ({start})" if start else key


def report(saved: dict[str, Any]) -> str:
    head = "| crop (bend, periods) | run | " + " | ".join(label for _, label, *_ in MEASURES) + " | wall s |"
    lines = [head, "|" + "---|" * (len(MEASURES) + 3)]
    pictures = []
    for name, crop in saved["crops"].items():
        label = f"{name} ({crop['bend']:.2f}: {crop['sheets']}; auto {crop['auto']})"
        for key, rows in crop["rows"].items():
            run = _label(key, rows)
            wall = float(np.median([r["wall"] for r in rows]))
            lines.append(f"| {label} | {run} | " + " | ".join(_cells(rows)) + f" | {wall:.1f} |")
        stem = crop.get("stem", Path(crop["file"]).stem)
        pictures.append(
            f"![{name}, surfaces](img/sheets-{stem}-surfaces.png) "
            f"![{name}, domains](img/sheets-{stem}-domains.png)"
        )
    foot = f"_Measured on {saved['machine']}; seeds {', '.join(map(str, SEEDS))}, {SIDE}^3._"
    return "\n".join([*lines, "", foot, "", *pictures])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--report", action="store_true", help="rewrite the docs from the saved JSON")
    parser.add_argument("--only", action="append", default=[], help="run only this method (repeatable)")
    parser.add_argument("--shifts", action="store_true", help="only print the choice on the shifted crops")
    args = parser.parse_args(argv)
    if args.shifts:
        print(shifts())
        return
    saved = json.loads(RESULTS.read_text()) if args.report else run(tuple(args.only))
    markdown = report(saved)
    write_section("sheets-crops", markdown, DOCS / "solid.md")
    print(markdown)


if __name__ == "__main__":
    main()
