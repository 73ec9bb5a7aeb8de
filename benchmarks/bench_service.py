"""Load on the job service: 20 concurrent small jobs on 2 workers, and status-poll latency while busy.

``python -m benchmarks.bench_service`` starts ``texsynth serve`` (embedded queue, 2 worker processes)
on a temporary data directory, submits 20 small ``wei-levoy`` jobs at once from 20 threads, polls
job status continuously until all have ended, and writes the figures to docs/benchmarks.md
(section "service"). :func:`run_load` is also what the integration test asserts on.
"""

from __future__ import annotations

import io
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from PIL import Image

from benchmarks._report import write_section
from tests.servers import free_port
from texsynth.app.client import Client, ServiceError

JOB = {"method": "wei-levoy", "params": {"width": 48, "height": 48, "levels": 2, "neighbourhood_size": 7}}


def fringe_png(side: int = 64, seed: int = 0) -> bytes:
    y, x = np.mgrid[0:side, 0:side]
    rng = np.random.default_rng(seed)
    image = 0.5 + 0.4 * np.sin(2 * np.pi * (0.8 * x + 0.6 * y) / 8) + 0.08 * rng.standard_normal((side, side))
    buf = io.BytesIO()
    Image.fromarray((np.clip(image, 0, 1) * 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def run_load(
    url: str, exemplar: bytes, n_jobs: int = 20, job: dict | None = None, timeout: float = 300
) -> dict:
    """Submit ``n_jobs`` at once, poll status until all end; returns counts, timings and latencies."""
    job = job or JOB
    client = Client(url, timeout=30)
    start = time.perf_counter()
    with ThreadPoolExecutor(n_jobs) as pool:
        submitted = list(
            pool.map(
                lambda i: client.submit(exemplar, method=job["method"], params=job["params"], seed=i),
                range(n_jobs),
            )
        )
    submit_s = time.perf_counter() - start
    ids = [j["id"] for j in submitted]
    latencies_busy: list[float] = []
    final: dict[str, dict] = {}
    deadline = time.monotonic() + timeout
    while len(final) < len(ids) and time.monotonic() < deadline:
        for job_id in ids:
            if job_id in final:
                continue
            t0 = time.perf_counter()
            record = client.job(job_id)
            elapsed = time.perf_counter() - t0
            if record["state"] in ("succeeded", "failed", "cancelled"):
                final[job_id] = record
            else:
                latencies_busy.append(elapsed)
        time.sleep(0.05)
    wall = time.perf_counter() - start
    states: dict[str, int] = {}
    for record in final.values():
        states[record["state"]] = states.get(record["state"], 0) + 1
    run_times = [r["elapsed"] for r in final.values() if r.get("elapsed")]
    return {
        "jobs": n_jobs,
        "ended": len(final),
        "lost": n_jobs - len(final),
        "states": states,
        "submit_s": submit_s,
        "wall_s": wall,
        "job_s_median": statistics.median(run_times) if run_times else float("nan"),
        "polls": len(latencies_busy),
        "poll_ms_median": 1000 * statistics.median(latencies_busy) if latencies_busy else float("nan"),
        "poll_ms_p95": 1000 * float(np.percentile(latencies_busy, 95)) if latencies_busy else float("nan"),
        "messages": sorted({r["message"] for r in final.values() if r["state"] != "succeeded"}),
    }


def main() -> int:
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        env = {**os.environ, "TEXSYNTH_CONCURRENCY": "2"}
        with open(Path(tmp) / "serve.log", "wb") as log:
            proc = subprocess.Popen(
                [
                    sys.executable,
                    "-c",
                    "import sys; from texsynth.synth.cli import main; sys.exit(main())",
                    "serve",
                    "--port",
                    str(port),
                    "--data-dir",
                    str(Path(tmp) / "data"),
                ],
                env=env,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        try:
            client = Client(f"http://127.0.0.1:{port}", timeout=5)
            deadline = time.monotonic() + 60
            while True:
                try:
                    if client.health().get("status") == "ok":
                        break
                except ServiceError:
                    pass  # not listening yet
                if time.monotonic() > deadline:
                    raise SystemExit("the service did not start")
                time.sleep(0.3)
            exemplar = fringe_png()
            warm = client.submit(exemplar, method=JOB["method"], params=JOB["params"])  # JIT caches, imports
            client.wait(warm["id"], timeout=300)
            figures = run_load(client.base_url, exemplar)
        except ServiceError as exc:
            raise SystemExit(str(exc)) from None
        finally:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(timeout=30)
    print(figures)
    params = ", ".join(f"{k}={v}" for k, v in JOB["params"].items())
    write_section(
        "service",
        "\n".join(
            [
                "## Job service under load",
                "",
                "`python -m benchmarks.bench_service`: `texsynth serve` on the embedded queue"
                " (filesystem broker, SQLite) with 2 worker processes;"
                f" {figures['jobs']} `{JOB['method']}` jobs ({params}) submitted at once"
                f" from {figures['jobs']} threads; job status polled continuously while they run.",
                "",
                "| figure | value |",
                "|---|---|",
                f"| jobs ended / lost | {figures['ended']} / {figures['lost']} ({figures['states']}) |",
                f"| submitting all jobs | {figures['submit_s']:.2f} s |",
                f"| all jobs ended after | {figures['wall_s']:.1f} s |",
                f"| run time of one job (median) | {figures['job_s_median']:.2f} s |",
                f"| status polls while busy | {figures['polls']} |",
                f"| status poll latency, median | {figures['poll_ms_median']:.1f} ms |",
                f"| status poll latency, 95th percentile | {figures['poll_ms_p95']:.1f} ms |",
            ]
        ),
    )
    ok = figures["lost"] == 0 and figures["states"].get("succeeded") == figures["jobs"]
    return 0 if ok and figures["poll_ms_median"] < 50 else 1


if __name__ == "__main__":
    sys.exit(main())
