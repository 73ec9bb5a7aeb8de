"""Load: 20 concurrent small jobs on the 2 worker processes all finish; status polls stay fast."""

from __future__ import annotations

import pytest

from benchmarks.bench_service import JOB, run_load

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def test_twenty_concurrent_jobs_all_finish_and_polls_stay_fast(embedded, exemplar_png):
    figures = run_load(embedded.url, exemplar_png, n_jobs=20, job=JOB, timeout=300)
    assert figures["lost"] == 0, figures
    assert figures["states"] == {"succeeded": 20}, figures
    assert figures["polls"] > 20
    assert figures["poll_ms_median"] < 50, figures
