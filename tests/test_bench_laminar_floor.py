"""``benchmarks.bench_laminar --floor N [--family F]``: the spread of independent truth samples against the
truth's blocks, for the onions and the turbostratic stack, every measure with its share of misses."""

from __future__ import annotations

import json

import pytest

from benchmarks import bench_laminar
from benchmarks.bench_laminar import _measure_spread, floor_distribution, main
from texsynth.synth.evaluate.truth import evaluate_against_truth, truth_slices
from texsynth.synth.io.laminar import turbostratic_volume


def test_measure_spread_counts_the_values_outside_the_target() -> None:
    ratio = _measure_spread([0.80, 1.00, 1.20, 1.15], 0.85, 1.15)  # 1.15 is on the band: a pass
    assert ratio["share_missed"] == pytest.approx(0.5)
    assert ratio["min"] == pytest.approx(0.80) and ratio["max"] == pytest.approx(1.20)
    ks = _measure_spread([0.10, 0.15, 0.20, 0.05], 0.0, 0.15)
    assert ks["share_missed"] == pytest.approx(0.25)
    assert ks["mean"] == pytest.approx(0.125) and ks["max"] == pytest.approx(0.20)


def test_floor_of_the_turbostratic_stack_measures_its_own_samples(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bench_laminar, "TRUTH_SIDE", 64)  # a small truth: the same machinery, quicker
    got = floor_distribution("turbostratic", samples=1, side=32)
    assert got["family"] == "turbostratic" and got["samples"] == 1
    ref = truth_slices(turbostratic_volume((64,) * 3, seed=bench_laminar.TRUTH_SEED), (32,) * 3)
    want = evaluate_against_truth(ref, turbostratic_volume((32,) * 3, seed=12))["summary"]["per_axis"]
    for key in ("fringe_ks_tortuosity", "fringe_ks_length", "orientation_kl", "coherence_ratio"):
        values = [want[a][key] for a in bench_laminar.AXES]
        block = got["measures"][key]
        assert block["seed_axes"] == 3
        assert block["max"] == pytest.approx(max(values)) and block["min"] == pytest.approx(min(values))
    assert got["tortuosity_ks"]["max"] == pytest.approx(got["measures"]["fringe_ks_tortuosity"]["max"])


def test_floor_names_a_wrong_family_or_sample_count() -> None:
    with pytest.raises(ValueError, match="family"):
        floor_distribution("graphite", samples=1)
    with pytest.raises(ValueError, match="samples"):
        floor_distribution("onions", samples=0)


def test_family_option_reaches_the_floor_and_needs_it(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    calls: list[tuple[str, int]] = []

    def fake(family: str, samples: int = 30, side: int = 64) -> dict[str, object]:
        calls.append((family, samples))
        return {"family": family}

    monkeypatch.setattr(bench_laminar, "floor_distribution", fake)
    assert main(["--floor", "2", "--family", "turbostratic"]) == 0
    assert main(["--floor", "3"]) == 0
    assert calls == [("turbostratic", 2), ("onions", 3)]
    assert json.loads(capsys.readouterr().out.splitlines()[0]) == {"family": "turbostratic"}
    with pytest.raises(SystemExit):
        main(["--family", "turbostratic"])
    assert "--family" in capsys.readouterr().err
