"""``texsynth evaluate``: the quantitative benchmark of a synthesis result against its exemplar.

``texsynth evaluate --exemplar EX --output OUT [--json] [--plots DIR] [--pixel-size NM]``

``OUT`` is a 2-D image, or a volume: a TIFF with more than one page is read with
:func:`synth.io.load_volume` and evaluated slice by slice along each axis
(:func:`synth.evaluate.evaluate_volume`). Prints a table, or the full metrics as JSON with
``--json``; ``--plots DIR`` also writes the comparison PNGs (:func:`synth.output.plots.write_plots`).
Bad input is one line on stderr and exit status 2 (handled by :func:`synth.cli.main`).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from synth.errors import InvalidInput

__all__ = ["format_table", "register", "run"]

_DESCRIPTION = """\
Compare a synthesis output with its exemplar (the benchmark of the volumetric-synthesis study,
Urs et al. 2012, section 3.2):

  grey levels  64-bin histograms, KL(exemplar || output) in nats; mean, std, skewness, kurtosis
  structure    energy-weighted orientation histograms (structure tensor, 7x7 window) and their KL;
               coherence; Log-Euclidean distance of the mean tensors
  fringes      HRTEM lattice fringes: count, length, tortuosity (length / end-to-end distance),
               Kolmogorov-Smirnov statistics of the distributions

OUTPUT may be a volume (a TIFF with several pages): every slice along each of the three axes
is compared with the exemplar, per axis and overall.
"""


def _is_stack(path: str) -> bool:
    """Whether ``path`` is a TIFF with more than one page (anything unreadable: no, load_image says why)."""
    import tifffile  # deferred: ``--help`` needs no image codecs

    try:
        with tifffile.TiffFile(path) as tif:
            return len(tif.pages) > 1
    except (OSError, tifffile.TiffFileError, ValueError):
        return False


def _num(value: Any, digits: int = 4) -> str:
    if value is None:
        return "-"
    if isinstance(value, int):
        return str(value)
    return f"{value:.{digits}f}"


def _columns(metrics: Mapping[str, Any]) -> list[tuple[str, Mapping[str, Any]]]:
    if metrics["kind"] == "volume":
        cols = [(f"axis {k}", block) for k, block in metrics["axes"].items()]
        return [*cols, ("all axes", metrics["overall"])]
    return [("output", metrics)]


def format_table(metrics: Mapping[str, Any]) -> str:
    """A plain-text table of the headline figures of ``evaluate_pair``/``evaluate_volume`` metrics."""
    cols = _columns(metrics)
    first = cols[0][1]
    pixel_size = metrics["settings"].get("pixel_size_nm")
    Getter = Callable[[Mapping[str, Any]], Any]
    # (section, label, value on the exemplar side or None, value on an output block)
    rows: list[tuple[str, str, Getter | None, Getter]] = [
        ("grey", "KL(exemplar || output), nats", None, lambda b: b["grey"]["kl"]),
    ]
    for key in ("mean", "std", "skewness", "kurtosis"):
        rows.append(
            (
                "grey",
                key,
                lambda b, k=key: b["moments"]["exemplar"][k],
                lambda b, k=key: b["moments"]["output"][k],
            )
        )
    rows += [
        ("structure", "orientation KL, nats", None, lambda b: b["structure"]["orientation_kl"]),
        (
            "structure",
            "dominant fringe direction, deg",
            lambda b: b["structure"]["dominant_structure_direction_deg"]["exemplar"],
            lambda b: b["structure"]["dominant_structure_direction_deg"]["output"],
        ),
        (
            "structure",
            "mean coherence",
            lambda b: b["structure"]["coherence_mean"]["exemplar"],
            lambda b: b["structure"]["coherence_mean"]["output"],
        ),
        ("structure", "coherence KL, nats", None, lambda b: b["structure"]["coherence_kl"]),
        ("structure", "Log-Euclidean, mean tensors", None, lambda b: b["structure"]["log_euclidean"]),
    ]
    if "fringes" in first:
        side_rows = [
            ("count", "count"),
            ("density per 10k px", "density_per_10k_px"),
            ("mean length, px", "mean_length"),
            ("median length, px", "median_length"),
        ]
        if pixel_size:
            side_rows += [("mean length, nm", "mean_length_nm"), ("median length, nm", "median_length_nm")]
        side_rows += [
            ("median tortuosity", "median_tortuosity"),
            ("share tortuosity > 1.5", "share_tortuous"),
        ]
        for label, key in side_rows:
            rows.append(
                (
                    "fringes",
                    label,
                    lambda b, k=key: b["fringes"]["exemplar"][k],
                    lambda b, k=key: b["fringes"]["output"][k],
                )
            )
        rows += [
            ("fringes", "KS statistic, length", None, lambda b: b["fringes"]["ks_length"]["statistic"]),
            (
                "fringes",
                "KS statistic, tortuosity",
                None,
                lambda b: b["fringes"]["ks_tortuosity"]["statistic"],
            ),
        ]

    header = ["", "", "exemplar", *(name for name, _ in cols)]
    table = [header]
    last_section = None
    for section, label, ex_get, out_get in rows:
        cells = [section if section != last_section else "", label]
        cells.append(_num(ex_get(first)) if ex_get else "")
        cells += [_num(out_get(block)) for _, block in cols]
        table.append(cells)
        last_section = section
    widths = [max(len(r[i]) for r in table) for i in range(len(header))]
    lines = []
    for r in table:
        left = f"{r[0]:<{widths[0]}}  {r[1]:<{widths[1]}}"
        right = "  ".join(f"{c:>{max(widths[i + 2], 9)}}" for i, c in enumerate(r[2:]))
        lines.append(f"{left}  {right}".rstrip())
    shape = metrics["shape"]
    target = "volume" if metrics["kind"] == "volume" else "output"
    title = (
        f"exemplar {'x'.join(map(str, shape['exemplar']))} vs {target} {'x'.join(map(str, shape[target]))}"
        + (f", {pixel_size:g} nm/px" if pixel_size else "")
    )
    return "\n".join([title, "", *lines])


def run(args: argparse.Namespace) -> int:
    """Load, evaluate, print; write plots on request."""
    from synth.evaluate import evaluate_pair, evaluate_volume
    from synth.io import load_image, load_volume

    exemplar = load_image(args.exemplar)
    options = {"pixel_size": args.pixel_size, "fringes": not args.no_fringes}
    if _is_stack(args.output):
        output = load_volume(args.output)
        metrics = evaluate_volume(exemplar, output, slice_step=args.slice_step, **options)
    else:
        output = load_image(args.output)
        metrics = evaluate_pair(exemplar, output, **options)
    if args.plots is not None:
        from synth.output.plots import write_plots  # deferred: matplotlib only when plots are asked for

        try:
            written = write_plots(exemplar, output, metrics, args.plots)
        except OSError as exc:
            raise InvalidInput(str(args.plots), f"cannot write the plots: {exc.strerror or exc}") from None
        if not args.json:
            print(f"plots: {', '.join(str(p) for p in written)}", file=sys.stderr)
    if args.json:
        print(json.dumps(metrics, indent=2, allow_nan=False))
    else:
        print(format_table(metrics))
    return 0


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (value > 0 and value < float("inf")):
        raise argparse.ArgumentTypeError(f"{text!r} must be a positive number")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 1")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``evaluate`` to the ``texsynth`` command line."""
    parser = subparsers.add_parser(
        "evaluate",
        help="compare an output image or volume with its exemplar: histograms, orientations, fringes",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--exemplar", required=True, metavar="EX", help="the exemplar image (PNG, TIFF, JPEG)"
    )
    parser.add_argument(
        "--output",
        required=True,
        metavar="OUT",
        help="the synthesis output: an image, or a volume as a multi-page TIFF",
    )
    parser.add_argument("--json", action="store_true", help="print all metrics as JSON instead of a table")
    parser.add_argument(
        "--plots", type=Path, metavar="DIR", help="also write the comparison plots (PNG) into DIR"
    )
    parser.add_argument(
        "--pixel-size",
        type=_positive_float,
        metavar="NM",
        help="nanometres per pixel, to report fringe lengths in nm (hrtem-soot images: about 0.0556)",
    )
    parser.add_argument(
        "--no-fringes",
        action="store_true",
        help="skip the fringe analysis (textures without lattice fringes)",
    )
    parser.add_argument(
        "--slice-step",
        type=_positive_int,
        default=1,
        metavar="N",
        help="volumes: evaluate every N-th slice along each axis (default 1: all)",
    )
    parser.set_defaults(func=run)
