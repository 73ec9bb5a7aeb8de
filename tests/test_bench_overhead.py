"""``benchmarks.bench_overhead``: the timeline's stage changes joined into segments, and the
cores busy in each (the process's CPU over the wall); the table's outside figures, probed and bare."""

from __future__ import annotations

import pytest

from benchmarks.bench_overhead import segments, summarise, timeline_table


def test_segments_join_a_stage_and_give_short_pieces_to_the_one_before() -> None:
    # (wall, process CPU, stage on top from here on)
    changes = [
        (0.0, 0.0, "imports"),
        (0.5, 0.5, "other"),  # 10 ms of parsing between imports: joined to them
        (0.51, 0.51, "imports"),
        (0.7, 0.7, "synthesis"),
        (1.7, 2.5, "imports"),  # a short import inside the synthesis
        (1.71, 2.51, "synthesis"),
        (2.0, 3.0, "plots"),
        (2.2, 3.2, "other"),
    ]
    got = segments(changes, threads=2)
    assert [s[0] for s in got] == ["imports", "synthesis", "plots"]
    _, start, wall, busy = got[1]
    assert start == pytest.approx(0.7) and wall == pytest.approx(1.3)
    assert busy == pytest.approx(2.3 / 1.3)  # both threads of the synthesis, and the short import
    assert got[0][3] == pytest.approx(1.0)  # one core busy during the imports: the other stood idle
    table = timeline_table("x", {"wall": 2.2, "cpu": 3.2, "load": 1.0, "timeline": changes}, 2)
    assert "| 0.70 | synthesis | 1.30 |" in table and "| 0.00 | imports | 0.70 | 1.00 | 0.70 |" in table


def test_cores_busy_is_capped_at_the_thread_count() -> None:
    got = segments([(0.0, 0.0, "synthesis"), (1.0, 3.0, "other")], threads=2)
    assert got == [("synthesis", 0.0, 1.0, 2.0)]


def test_outside_without_the_probe_is_each_bare_run_less_its_probed_synthesis() -> None:
    def probed(synthesis: tuple[float, float], wall: float, cpu: float) -> dict:
        stages = {"synthesis": synthesis, "imports": (0.5, 0.5)}
        return {"stages": stages, "wall": wall, "cpu": cpu, "load": 1.0}

    runs = [probed((1.0, 1.8), 2.0, 3.0), probed((1.2, 2.0), 2.3, 3.3), probed((1.1, 1.9), 2.1, 3.1)]
    bare = [{"wall": 1.9, "cpu": 2.8}, {"wall": 2.1, "cpu": 3.1}, {"wall": 2.0, "cpu": 2.95}]
    got = summarise(runs, bare)
    assert got["outside_wall"] == pytest.approx(1.0) and got["outside_cpu"] == pytest.approx(1.2)
    # pairs: (0.9, 1.0), (0.9, 1.1), (0.9, 1.05): medians 0.9 and 1.05
    assert got["plain_outside_wall"] == pytest.approx(0.9)
    assert got["plain_outside_cpu"] == pytest.approx(1.05)
    assert got["plain_wall"] == pytest.approx(2.0)
    assert "plain_wall" not in summarise(runs)  # the timeline's runs have no bare twin
