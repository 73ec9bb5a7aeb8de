"""Solid textures from 2D exemplars: the volumetric-synthesis study's benchmark, reproduced.

Run: ``python -m benchmarks.bench_solid`` (writes docs/solid.md with its figures, and the ``solid`` section
of docs/benchmarks.md). ``--quick`` runs one seed of the 12-row table only. Every run rewrites only what it
measures: docs/solid.md's hand-written part (issue 24's sections, the verdict, the departures; from
:data:`KEPT_FROM` on) is kept as the file has it (:func:`kept_parts`).

1. **The study's table** (methods x scan orders = 12 rows) on HRTEM soot (``hrtem-soot-128.png``) and on a
   generated bent-laminae exemplar (128 x 128), 64^3 each at the methods' default (the papers') settings:
   time, and per axis (the slices normal to z, y and x, i.e. the xy, xz and yz planes) the multi-2D
   measures of :func:`texsynth.synth.evaluate.evaluate_volume`: grey-level KL, std and skewness differences,
   orientation KL, fringe length and tortuosity distances (Kolmogorov-Smirnov), and the two-point
   correlation's relative error.
2. **Fidelity targets** (issue 10): ``solid-kopf`` grey KL < 0.05 and orientation KL < 0.10 on every axis
   (Hilbert scan, the study's recommendation; defaults otherwise); ``solid-chen-wang`` within 1.5x.
3. **Anisotropic material** from three per-plane exemplars (laminae running along different directions in
   each plane): each axis's slices against their own exemplar's orientation distribution.
4. **Speed and memory** (2 cores): 64^3 from 64^2 and 128^3 from 128^2 (median of runs, peak resident
   memory of a fresh process), a 256^3 run with its progress, and fast against exact search on a small
   volume (mean best-match distance ratio).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._report import DATA, median_time, write_section
from texsynth.synth.api import synthesize
from texsynth.synth.evaluate import evaluate_volume
from texsynth.synth.evaluate.correlation import compare_s2, volume_s2
from texsynth.synth.io import load_image, save_image
from texsynth.synth.io.patterns import gaussian_random_field, laminae_volume, undulating_laminae

DOCS = Path(__file__).resolve().parent.parent / "docs"
METHODS = ("solid-wei-levoy", "solid-kopf", "solid-chen-wang")
SCANS = ("lexicographic", "random", "morton", "hilbert")
AXES = (("0", "xy (z)"), ("1", "xz (y)"), ("2", "yz (x)"))
SIZE = (64, 64, 64)
MEASURES = (
    ("grey_kl", "grey KL"),
    ("std_difference", "std diff"),
    ("skewness_difference", "skew diff"),
    ("orientation_kl", "orient. KL"),
    ("fringe_ks_length", "length KS"),
    ("fringe_ks_tortuosity", "tortuosity KS"),
    ("s2_relative_error", "S2 error"),
)


def exemplars() -> dict[str, np.ndarray]:
    """The two exemplars of the table: real HRTEM soot and generated bent laminae, 128 x 128."""
    out = {"laminae-bent-128": undulating_laminae((128, 128), 7, 16, 128, noise=0.3)}
    soot = DATA / "hrtem-soot-128.png"
    if soot.exists():
        out = {"hrtem-soot-128": load_image(soot), **out}
    return out


def per_axis(metrics: dict[str, Any]) -> dict[str, dict[str, float]]:
    """``{axis: {measure: value}}`` from :func:`evaluate_volume`'s summary (axis '0' = xy slices)."""
    return {axis: metrics["summary"]["per_axis"][axis] for axis, _ in AXES}


def run_row(method: str, scan: str, exemplar: np.ndarray, seed: int = 1) -> dict[str, Any]:
    start = time.perf_counter()
    result = synthesize(method, exemplar, size=SIZE, params={"scan": scan}, seed=seed)
    seconds = time.perf_counter() - start
    metrics = evaluate_volume(exemplar, result.image)
    return {"seconds": seconds, "axes": per_axis(metrics), "volume": result.image}


def _fmt(value: Any) -> str:
    if value is None:
        return "n/a"
    return f"{value:.3f}" if abs(value) < 100 else f"{value:.0f}"


def table(rows: list[dict[str, Any]]) -> str:
    """One row per method x scan; per measure, the three axes as ``xy / xz / yz``."""
    head = "| method | scan | time (s) | " + " | ".join(label for _, label in MEASURES) + " |"
    lines = [head, "|" + "---|" * (3 + len(MEASURES))]
    for row in rows:
        cells = [" / ".join(_fmt(row["axes"][axis].get(key)) for axis, _ in AXES) for key, _ in MEASURES]
        lines.append(
            f"| `{row['method']}` | {row['scan']} | {row['seconds']:.1f} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


def slices_figure(volume: np.ndarray, exemplar: np.ndarray) -> np.ndarray:
    """Exemplar | xy | xz | yz mid-slices side by side (grey, 4 px white gutters)."""
    d, h, w = volume.shape
    parts = [exemplar, volume[d // 2], volume[:, h // 2, :], volume[:, :, w // 2]]
    side = max(p.shape[0] for p in parts)
    gutter = np.ones((side, 4), np.float32)
    tiles = []
    for part in parts:
        tile = np.ones((side, part.shape[1]), np.float32)
        tile[: part.shape[0]] = part
        tiles += [tile, gutter]
    return np.concatenate(tiles[:-1], axis=1)


def _laminae_planes(normal: tuple[float, float, float]) -> dict[str, np.ndarray]:
    """The three orthogonal mid-slices (128^2) of a 128^3 volume of bent sheets: consistent exemplars."""
    vol = laminae_volume((128, 128, 128), normal, 7, 6, 64, noise=0.2, seed=1)
    return {"xy": vol[64], "xz": vol[:, 64, :], "yz": vol[:, :, 64]}


def _kl_cells(kls: list[list[float]]) -> str:
    """Per axis, the mean over seeds and the worst seed: ``mean (worst)``."""
    cells = []
    for axis in range(3):
        values = [k[axis] for k in kls]
        cells.append(f"{statistics.mean(values):.3f} ({max(values):.3f})")
    return " | ".join(cells)


ANISOTROPIC_RUNS = (
    ("solid-kopf", {}),
    ("solid-kopf", {"orientation_gain": 0.0}),
    ("solid-kopf", {"adapt_to_structure": False}),
    ("solid-kopf", {"structure": "oriented"}),
    ("solid-kopf", {"structure": "oriented", "oriented_length": "auto"}),
    ("solid-chen-wang", {}),
)


def anisotropic(seeds: tuple[int, ...] = (1, 2, 3)) -> tuple[str, dict[str, float]]:
    """Per-plane exemplars of a laminated material that exists: each axis against its own exemplar.

    The exemplars are the mid-slices of bent sheets normal to z (:func:`laminae_volume`): the xz and yz
    slices are bent horizontal laminae, the xy slices cut the sheets into contour bands.
    """
    planes = _laminae_planes((1.0, 0.0, 0.0))
    out = {}
    lines = [
        "| method | parameters | xy orient. KL | xz orient. KL | yz orient. KL | time (s) |",
        "|---|---|---|---|---|---|",
    ]
    for method, extra in ANISOTROPIC_RUNS:
        kls, times = [], []
        for seed in seeds:
            start = time.perf_counter()
            result = synthesize(method, exemplars=planes, size=SIZE, params=extra, seed=seed)
            times.append(time.perf_counter() - start)
            axes = per_axis(evaluate_volume(planes, result.image, fringes=False))
            kls.append([axes[axis]["orientation_kl"] for axis, _ in AXES])
            if seed == seeds[0]:
                tag = "-".join(f"{k}{v}" for k, v in extra.items()) or "defaults"
                save_image(
                    DOCS / "img" / f"solid-anisotropic-{method}-{tag}.png",
                    slices_figure(result.image, planes["xz"]),
                )
        label = ", ".join(f"{k}={v}" for k, v in extra.items()) or "defaults"
        out[f"{method} {label}"] = max(max(k) for k in kls)
        lines.append(f"| `{method}` | {label} | {_kl_cells(kls)} | {statistics.median(times):.1f} |")
    return "\n".join(lines), out


TWO_VIEW_RUNS = (
    ("solid-kopf", {}),
    ("solid-kopf", {"orientation_gain": 0.0}),
    ("solid-kopf", {"structure": "oriented"}),
    ("solid-kopf", {"structure": "oriented", "oriented_length": "auto"}),
    ("solid-chen-wang", {}),
)


def two_views(seeds: tuple[int, ...] = (1, 2, 3)) -> str:
    """The bent-laminae exemplar on the two planes that admit a volume (``planes=('xz', 'yz')``: sheets
    normal to z, bent both ways), each against the exemplar; the xy slices are free (contour bands)."""
    exemplar = exemplars()["laminae-bent-128"]
    lines = [
        "| method | parameters | xz orient. KL | yz orient. KL | xz grey KL | yz grey KL | time (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for method, extra in TWO_VIEW_RUNS:
        params = {**extra, "planes": ("xz", "yz")}
        kls, greys, times = [], [], []
        for seed in seeds:
            start = time.perf_counter()
            result = synthesize(method, exemplar, size=SIZE, params=params, seed=seed)
            times.append(time.perf_counter() - start)
            axes = per_axis(evaluate_volume(exemplar, result.image, fringes=False))
            kls.append([axes[axis]["orientation_kl"] for axis in ("1", "2")])
            greys.append([axes[axis]["grey_kl"] for axis in ("1", "2")])
            if seed == seeds[0]:
                tag = "-".join(f"{k}{v}" for k, v in extra.items()) or "defaults"
                save_image(
                    DOCS / "img" / f"solid-two-views-{method}-{tag}.png",
                    slices_figure(result.image, exemplar),
                )
        label = ", ".join(f"{k}={v}" for k, v in extra.items()) or "defaults"
        cells = []
        for values in (kls, greys):
            for axis in range(2):
                column = [v[axis] for v in values]
                cells.append(f"{statistics.mean(column):.3f} ({max(column):.3f})")
        lines.append(f"| `{method}` | {label} | {' | '.join(cells)} | {statistics.median(times):.1f} |")
    return "\n".join(lines)


def diagonal_laminae(seed: int = 1) -> str:
    """One laminae exemplar for all three planes, where a consistent volume exists (sheets normal to
    (1, 1, 1)): the xy mid-slice of such a volume given as the single exemplar."""
    exemplar = _laminae_planes((1.0, 1.0, 1.0))["xy"]
    lines = ["| method | xy orient. KL | xz orient. KL | yz orient. KL | time (s) |", "|---|---|---|---|---|"]
    for method in ("solid-kopf", "solid-chen-wang"):
        start = time.perf_counter()
        result = synthesize(method, exemplar, size=SIZE, seed=seed)
        seconds = time.perf_counter() - start
        axes = per_axis(evaluate_volume(exemplar, result.image, fringes=False))
        kls = " | ".join(f"{axes[a]['orientation_kl']:.3f}" for a, _ in AXES)
        lines.append(f"| `{method}` | {kls} | {seconds:.1f} |")
        save_image(DOCS / "img" / f"solid-diagonal-{method}.png", slices_figure(result.image, exemplar))
    return "\n".join(lines)


def known_answer(seeds: tuple[int, ...] = (1, 2, 3)) -> str:
    """S2 along each axis of 32^3 volumes synthesized from the mid-slices of a level-cut Gaussian random
    field (correlation lengths 2, 3.5, 6 along z, y, x), against the field's own (the test's case)."""
    truth = gaussian_random_field((64, 64, 64), (2.0, 3.5, 6.0), 0.4, seed=11)
    planes = {"xy": truth[32], "xz": truth[:, 32, :], "yz": truth[:, :, 32]}
    want = volume_s2(truth, threshold=0.5, periodic=True, max_lag=16)
    lines = ["| method | levels used | S2 error z | S2 error y | S2 error x |", "|---|---|---|---|---|"]
    for method, label, extra in (
        ("solid-kopf", "defaults (adaptive levels)", {}),
        ("solid-kopf", "the paper's 5 levels", {"adapt_to_structure": False}),
        ("solid-chen-wang", "defaults", {}),
        ("solid-chen-wang", "grey_weight=5 (before session 5)", {"grey_weight": 5.0}),
    ):
        errors, used = [], set()
        for seed in seeds:
            result = synthesize(method, exemplars=planes, size=(32, 32, 32), params=extra, seed=seed)
            used.add(result.stats["levels"])
            got = volume_s2(result.image, threshold=0.5, periodic=True, max_lag=16)
            errors.append([compare_s2(want[a], got[a])["relative_error"] for a in "zyx"])
        cells = _kl_cells(errors)
        lines.append(f"| `{method}` {label} | {', '.join(map(str, sorted(used)))} | {cells} |")
    return "\n".join(lines)


_MEMORY_SCRIPT = """
import resource, sys, time, numpy as np
from texsynth.synth.api import synthesize
from texsynth.synth.io import load_image
n, method = int(sys.argv[1]), sys.argv[2]
ex = load_image(sys.argv[3])[:n, :n].copy() if sys.argv[3] != "-" else None
if ex is None:
    from texsynth.synth.io.patterns import undulating_laminae
    ex = undulating_laminae((n, n), 7, 16, 128, noise=0.3)
marks = []
def progress(stage, fraction):
    if not marks or fraction - marks[-1][1] >= 0.1 or fraction == 1.0:
        marks.append((time.perf_counter(), fraction))
start = time.perf_counter()
synthesize(method, ex, size=(n, n, n), seed=1, progress=progress)
print(time.perf_counter() - start, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, len(marks))
"""


def fresh_process(n: int, method: str) -> tuple[float, float, int]:
    """Seconds, peak resident MiB and progress reports of one ``n^3`` run in a new process."""
    soot = DATA / "hrtem-soot-256.png"
    source = str(soot) if soot.exists() else "-"
    out = subprocess.run(
        [sys.executable, "-c", _MEMORY_SCRIPT, str(n), method, source],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return float(out[0]), float(out[1]), int(out[2])


def speed(runs: int, big: bool = False) -> str:
    lines = ["| method | size | median (s) | runs | peak memory (MiB) |", "|---|---|---|---|---|"]
    soot = DATA / "hrtem-soot-256.png"
    source = load_image(soot) if soot.exists() else undulating_laminae((256, 256), 7, 16, 128, noise=0.3)
    for method in ("solid-kopf", "solid-chen-wang"):
        for n in (64, 128):
            ex = np.ascontiguousarray(source[:n, :n])
            med, times = median_time(
                lambda ex=ex, n=n, method=method: synthesize(method, ex, size=(n, n, n), seed=1),
                runs=runs if n == 64 else max(1, runs // 2),
            )
            _, mib, _ = fresh_process(n, method)
            shown = ", ".join(f"{t:.1f}" for t in times)
            lines.append(f"| `{method}` | {n}^3 from {n}^2 | {med:.1f} | {shown} | {mib:.0f} |")
    if big:
        seconds, mib, marks = fresh_process(256, "solid-kopf")
        once = f"{seconds:.0f} (one run, {marks} progress reports)"
        lines.append(f"| `solid-kopf` | 256^3 from 256^2 | {once} | 1 | {mib:.0f} |")
    return "\n".join(lines)


def fast_against_exact(seed: int = 1) -> str:
    """Mean best-match distance of the default (fast) search over the exact one, on a 24^3 volume."""
    ex = np.ascontiguousarray(undulating_laminae((48, 48), 7, 8, 48, noise=0.3))
    lines = ["| method | fast / exact mean best distance |", "|---|---|"]
    for method in ("solid-kopf",):
        dist = {}
        for search in ("tree", "exact"):
            result = synthesize(method, ex, size=(24, 24, 24), params={"search": search}, seed=seed)
            per_level = result.stats["mean_best_distance"]  # coarse first: the last is the finest level
            dist[search] = float(list(per_level.values())[-1] if isinstance(per_level, dict) else per_level)
        lines.append(f"| `{method}` | {dist['tree'] / dist['exact']:.3f} |")
    return "\n".join(lines)


GEOMETRY = """## Laminae and one exemplar for three planes: when a volume exists

Slices of sheets whose normal is ``n = (n_z, n_y, n_x)`` show laminae whose gradient, in each plane's
(row, column) axes, is ``(n_y, n_x)`` in xy, ``(n_z, n_x)`` in xz and ``(n_z, n_y)`` in yz
(`texsynth.synth.api.PLANES`). One exemplar for the three planes asks the three gradients to make the same
angle: ``n_y / n_x = n_z / n_x = n_z / n_y = t``. The first two give ``n_z = n_y``, so the third gives
``t = 1``: **only laminae whose gradient points along the image diagonal (fringes running from bottom
left to top right, sheets normal to (1, 1, 1)) can appear on all three planes**; any other uniaxial
exemplar, horizontal laminae included, describes no volume at all, and the bent-laminae rows of the
table above measure that impossibility, not the methods. A mixture of sheet families does not help:
a family that shows the exemplar's orientation in one plane shows another in the next. For laminar
materials the per-plane inputs (`--exemplar-xy/--exemplar-xz/--exemplar-yz`, three micrographs of the
same material) or the two-view mode (`planes=('xz', 'yz')`) are the right tools.
"""

#: Where docs/solid.md's hand-written part begins (issue 24's sections, the verdict, the departures from the
#: papers and their history): every run keeps it as the file has it, and writes only what it measures.
KEPT_FROM = "## Laminar HRTEM: the structure first"
#: The first of the sections :func:`_extra_sections` writes, and the speed section (last in the file).
EXTRAS_FROM = "## Laminae and one exemplar"
SPEED_FROM = "## Speed and memory"
FAST_FROM = "## Fast against exact search"


def kept_parts(text: str) -> dict[str, str]:
    """The parts of docs/solid.md (``text``) that a run does not re-measure, as the file has them:
    ``'extras'`` (the laminae, anisotropic and known-answer sections, and the search section),
    ``'fast'`` (that search section alone), ``'kept'`` (the hand-written part, from :data:`KEPT_FROM` up
    to the speed section) and ``'speed'``; ``''`` for a part the file lacks."""

    def between(start: str, *ends: str) -> str:
        at = text.find(start)
        if at < 0:
            return ""
        stops = [i for i in (text.find(end, at + 1) for end in ends) if i >= 0]
        return text[at : min(stops) if stops else len(text)].rstrip()

    return {
        "extras": between(EXTRAS_FROM, KEPT_FROM, SPEED_FROM),
        "fast": between(FAST_FROM, KEPT_FROM, SPEED_FROM),
        "kept": between(KEPT_FROM, SPEED_FROM),
        "speed": between(SPEED_FROM),
    }


def _extra_sections() -> list[str]:
    """The sections after the tables: laminae geometry, diagonal laminae, anisotropic, known answer."""
    aniso, _ = anisotropic()
    return [
        GEOMETRY,
        "### One exemplar where a consistent volume exists: laminae at the diagonal\n\n"
        "The exemplar is the xy mid-slice of sheets normal to (1, 1, 1); its xz and yz mid-slices "
        f"look the same.\n\n{diagonal_laminae()}\n\n"
        "![kopf](img/solid-diagonal-solid-kopf.png) "
        "![chen-wang](img/solid-diagonal-solid-chen-wang.png)\n",
        "### Bent laminae on the two planes that admit a volume\n\n"
        "The table's bent-laminae exemplar given to the xz and yz planes only (`planes=('xz', 'yz')`): "
        "sheets normal to z bent both ways satisfy both, and the xy slices (free) cut them into contour "
        "bands. 64^3, mean over seeds 1-3 (worst); target < 0.10.\n\n"
        f"{two_views()}\n\n"
        "Exemplar, then the xy, xz and yz mid-slices, seed 1: `solid-kopf` (defaults), the same without "
        "the orientation re-weighting, from the oriented start (crumples of 2 periods, then fitted), "
        "`solid-chen-wang`:\n\n"
        "![kopf](img/solid-two-views-solid-kopf-defaults.png) "
        "![kopf, gain 0](img/solid-two-views-solid-kopf-orientation_gain0.0.png) "
        "![kopf, oriented](img/solid-two-views-solid-kopf-structureoriented.png) "
        "![kopf, oriented, fitted](img/solid-two-views-solid-kopf-structureoriented-oriented_lengthauto.png) "
        "![chen-wang](img/solid-two-views-solid-chen-wang-defaults.png)\n",
        "## Anisotropic material from three per-plane exemplars (64^3 from 128^2)\n\n"
        "The exemplars are the three mid-slices of bent sheets normal to z (a material that exists). "
        "Cells: mean over seeds 1-3 (worst seed); target < 0.10 on every axis.\n\n"
        f"{aniso}\n\n"
        "Exemplar (xz), then the xy, xz, yz mid-slices, seed 1: defaults (10 iterations, orientation "
        "re-weighting), without the re-weighting, 4 iterations, the oriented start (2 periods, fitted), "
        "chen-wang:\n\n"
        "![defaults](img/solid-anisotropic-solid-kopf-defaults.png) "
        "![gain 0](img/solid-anisotropic-solid-kopf-orientation_gain0.0.png) "
        "![4 iterations](img/solid-anisotropic-solid-kopf-adapt_to_structureFalse.png) "
        "![oriented](img/solid-anisotropic-solid-kopf-structureoriented.png) "
        "![oriented, fitted](img/solid-anisotropic-solid-kopf-structureoriented-oriented_lengthauto.png) "
        "![chen-wang](img/solid-anisotropic-solid-chen-wang-defaults.png)\n",
        "## Known answer: S2 of a level-cut Gaussian random field\n\n"
        "32^3 from the three 64^2 mid-slices of a 64^3 two-phase field; relative L1 error of S2 up to "
        "the truth's correlation length, mean over seeds 1-3 (worst); target < 0.10 "
        f"(tests/synth/methods/test_solid_known_answer.py).\n\n{known_answer()}\n",
    ]


def refresh(method: str, text: str) -> str:
    """``text`` (docs/solid.md) with ``method``'s table rows and :func:`_extra_sections` re-run.

    The rows of the other methods, the figures of the tables, the hand-written part (:func:`kept_parts`)
    and the speed section are kept as the file has them; a note under the title says which rows are newer.
    """
    if method not in METHODS:
        raise SystemExit(f"--refresh takes one of {', '.join(METHODS)}; got {method!r}")
    for name, exemplar in exemplars().items():
        head = text.index(f"## {name}")
        for scan in SCANS:
            row = run_row(method, scan, exemplar)
            row.update(method=method, scan=scan)
            print(f"{name} {method} {scan}: {row['seconds']:.1f} s", flush=True)
            new_line = table([row]).splitlines()[-1]
            prefix = f"| `{method}` | {scan} |"
            at = text.index(prefix, head)
            end = text.index("\n", at)
            text = text[:at] + new_line + text[end:]
            if scan == "hilbert":
                save_image(
                    DOCS / "img" / f"solid-{name}-{method}.png", slices_figure(row["volume"], exemplar)
                )
    parts = kept_parts(text)
    first_extra = min(i for i in (text.find(EXTRAS_FROM), text.find(KEPT_FROM), len(text)) if i >= 0)
    note = (
        f"\n\nThe `{method}` rows were re-run after a change to that method alone "
        "(`python -m benchmarks.bench_solid --refresh " + method + "`); the other rows are from the "
        "full run before it."
    )
    title_end = text.index("\n\n## ")
    body = text[:title_end] + (note if note.strip() not in text else "") + text[title_end:first_extra]
    later = [*_extra_sections(), parts["fast"], parts["kept"], parts["speed"]]
    return body.rstrip() + "\n\n" + "\n\n".join(p for p in later if p).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="the solid-synthesis benchmark")
    parser.add_argument("--quick", action="store_true", help="the 12-row table only")
    parser.add_argument("--big", action="store_true", help="also a 256^3 run (several minutes)")
    parser.add_argument(
        "--refresh",
        metavar="METHOD",
        help="re-run one method's table rows and the laminae, anisotropic and known-answer sections, "
        "keeping the rest of docs/solid.md (after a change to that method only)",
    )
    args = parser.parse_args(argv)
    (DOCS / "img").mkdir(parents=True, exist_ok=True)
    existing = kept_parts((DOCS / "solid.md").read_text()) if (DOCS / "solid.md").exists() else {}
    if args.refresh:
        (DOCS / "solid.md").write_text(refresh(args.refresh, (DOCS / "solid.md").read_text()))
        return 0
    sections = [
        "# Solid textures from 2D exemplars\n\n"
        "Generated by `python -m benchmarks.bench_solid` (see its docstring for what each table measures). "
        "Per-axis cells read `xy / xz / yz`: the slices normal to z, y and x, each compared with the "
        "exemplar by the study's multi-2D measures (`texsynth.synth.evaluate.evaluate_volume`; grey and "
        "orientation "
        "KL of the pooled histograms, differences of std and skewness, Kolmogorov-Smirnov distances of "
        "fringe length and tortuosity, relative error of the two-point correlation S2 up to the exemplar's "
        "correlation length). Every volume is 64^3 from a 128^2 exemplar, seed 1, default parameters "
        "(the papers' settings) but the scan order."
    ]
    summary: dict[str, Any] = {}
    for name, exemplar in exemplars().items():
        rows = []
        for method in METHODS:
            for scan in SCANS:
                row = run_row(method, scan, exemplar)
                row.update(method=method, scan=scan)
                rows.append(row)
                print(f"{name} {method} {scan}: {row['seconds']:.1f} s", flush=True)
                if scan == "hilbert":
                    save_image(
                        DOCS / "img" / f"solid-{name}-{method}.png", slices_figure(row["volume"], exemplar)
                    )
        sections.append(f"## {name}\n\n{table(rows)}\n")
        figures = " ".join(f"![{m}](img/solid-{name}-{m}.png)" for m in METHODS)
        sections.append(
            f"Exemplar, then the xy, xz and yz mid-slices (Hilbert scan), one method a row:\n\n{figures}\n"
        )
        summary[name] = {
            f"{r['method']}:{r['scan']}": {
                "seconds": r["seconds"],
                "max_grey_kl": max(r["axes"][a]["grey_kl"] for a, _ in AXES),
                "max_orientation_kl": max(r["axes"][a]["orientation_kl"] for a, _ in AXES),
            }
            for r in rows
        }
    (DOCS / "solid-benchmark.json").write_text(json.dumps(summary, indent=2) + "\n")
    speed_section = existing.get("speed", "")
    if args.quick:
        sections.append(existing.get("extras", ""))
    else:
        sections.extend(_extra_sections())
        fast = fast_against_exact()
        sections.append(f"## Fast against exact search (24^3 from 48^2 laminae)\n\n{fast}\n")
        timing = speed(runs=3, big=args.big)
        speed_section = f"## Speed and memory (2 cores)\n\n{timing}\n"
        write_section("solid", f"## Solid synthesis\n\n{timing}\n\n{fast}\n")
    sections.extend([existing.get("kept", ""), speed_section])
    (DOCS / "solid.md").write_text("\n\n".join(x.rstrip() for x in sections if x) + "\n")
    best = {
        name: min(rows.items(), key=lambda kv: kv[1]["max_orientation_kl"] + kv[1]["max_grey_kl"])[0]
        for name, rows in summary.items()
    }
    print("best (grey + orientation KL, worst axis):", best)
    print(
        "median seconds per method:",
        {
            m: statistics.median(
                r["seconds"] for rows in summary.values() for k, r in rows.items() if k.startswith(m + ":")
            )
            for m in METHODS
        },
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
