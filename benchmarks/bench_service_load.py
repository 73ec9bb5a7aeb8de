"""Load with faults: 100 small jobs from 10 clients on 2 workers, one worker child killed mid-run,
and (on Redis) redis-server restarted mid-run; every job accounted for in the job records.

``python -m benchmarks.bench_service_load [--queue embedded|redis|both] [--jobs 100] [--clients 10]``
starts ``texsynth serve`` (2 worker processes; the embedded queue, or a ``redis-server`` it starts on a
free loopback port without persistence) on a temporary data directory, runs one warm-up job, then
10 client threads each submit their share of ``random-phase`` 64x64 jobs one after another (submit,
poll until it ends, next), retrying a submission the service refuses with 503 or cannot be reached.
When 20 jobs have ended it SIGKILLs the worker child running a job; on Redis, when 50 have ended it
shuts redis-server down (``SHUTDOWN NOSAVE``: every queued message is gone) and starts it again
3 s later. Then it reads the job store: succeeded, failed, lost (submitted but never ended, or no
record), duplicated (a record no client was answered with, or one id answered twice), re-runs
(attempts > 1). Not a unit test: it writes the "load" section of docs/benchmarks.md and exits 1
unless every job succeeded exactly once.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import signal
import socket
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
from PIL import Image

from benchmarks._report import write_section
from tests.service.conftest import Service, free_port, start_redis
from texsynth.app.client import Client, Retry, ServiceError

JOB = {"method": "random-phase", "params": {"width": 64, "height": 64}}
ENDED = ("succeeded", "failed", "cancelled")
#: production defaults where the test fixture shortens them (a dead run is noticed after 10 s)
ENV = {"TEXSYNTH_STALE_SECONDS": "10", "TEXSYNTH_CANCEL_GRACE_SECONDS": "2"}


def exemplar_png(side: int = 48, seed: int = 0) -> bytes:
    y, x = np.mgrid[0:side, 0:side]
    rng = np.random.default_rng(seed)
    image = 0.5 + 0.4 * np.sin(2 * np.pi * (0.8 * x + 0.6 * y) / 8) + 0.08 * rng.standard_normal((side, side))
    buf = io.BytesIO()
    Image.fromarray((np.clip(image, 0, 1) * 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _children(pid: int) -> list[int]:
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(entry.name))
    return out


def _redis_shutdown(port: int) -> None:
    with socket.create_connection(("127.0.0.1", port), timeout=2) as s:
        s.sendall(b"SHUTDOWN NOSAVE\r\n")
        s.settimeout(2)
        with contextlib.suppress(OSError):
            s.recv(64)


class Run:
    """Clients, fault injection and the bookkeeping of one load run."""

    def __init__(self, service: Service, exemplar: bytes, n_jobs: int, n_clients: int) -> None:
        self.service, self.exemplar = service, exemplar
        self.n_jobs, self.n_clients = n_jobs, n_clients
        self.lock = threading.Lock()
        self.answered: list[str] = []  # ids the API answered submissions with
        self.ended: dict[str, str] = {}  # id -> final state seen by its client
        self.submit_retries = 0
        self.poll_errors = 0
        self.errors: list[str] = []
        self.events: list[str] = []
        self.t0 = 0.0
        self.load_max = 0.0

    def note(self, text: str) -> None:
        with self.lock:
            self.events.append(f"{time.perf_counter() - self.t0:5.1f} s {text}")
        print(self.events[-1], flush=True)

    def client_loop(self, index: int, deadline: float) -> None:
        # no retries inside the client: this run counts the service's refusals and failed polls itself
        client = Client(self.service.url, timeout=30, retry=Retry(attempts=1))
        share = range(index, self.n_jobs, self.n_clients)
        for seed in share:
            job = None
            while job is None and time.monotonic() < deadline:
                try:
                    job = client.submit(self.exemplar, method=JOB["method"], params=JOB["params"], seed=seed)
                except (ServiceError, OSError) as exc:
                    if isinstance(exc, ServiceError) and exc.status not in (502, 503, 504):
                        with self.lock:
                            self.errors.append(f"submit {seed}: {exc}")
                        break
                    with self.lock:
                        self.submit_retries += 1
                    time.sleep(0.5)
            if job is None:
                continue
            with self.lock:
                self.answered.append(job["id"])
            while time.monotonic() < deadline:
                try:
                    state = client.job(job["id"])["state"]
                except (ServiceError, OSError):
                    with self.lock:
                        self.poll_errors += 1
                    state = None
                if state in ENDED:
                    with self.lock:
                        self.ended[job["id"]] = state
                    break
                time.sleep(0.2)

    def kill_a_worker_child(self) -> None:
        store = self.service.store()
        running = [j for j in store.active() if j.state == "running" and j.pid]
        if running:
            pid, why = running[0].pid, f"running job {running[0].id[:8]}"
        else:  # nothing running at this instant: any child of the worker
            pid, why = _children(self.service.worker_pid())[0], "idle"
        os.kill(pid, signal.SIGKILL)
        self.note(f"kill -9 worker child {pid} ({why})")


def run(queue: str, n_jobs: int, n_clients: int, timeout: float) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(ENV)
        redis = redis_port = None
        if queue == "redis":
            redis_port = free_port()
            redis = start_redis(redis_port, tmp)
            env["REDIS_URL"] = f"redis://127.0.0.1:{redis_port}/0"
        service = Service(Path(tmp) / "data", env, concurrency=2)
        try:
            service.start()
            client = service.client()
            exemplar = exemplar_png()
            warm = client.submit(exemplar, method=JOB["method"], params=JOB["params"])
            client.wait(warm["id"], timeout=120)
            r = Run(service, exemplar, n_jobs, n_clients)
            r.t0 = time.perf_counter()
            load_start = os.getloadavg()[0]
            deadline = time.monotonic() + timeout
            threads = [
                threading.Thread(target=r.client_loop, args=(i, deadline), daemon=True)
                for i in range(n_clients)
            ]
            for t in threads:
                t.start()
            killed, restarted = False, queue != "redis"
            while any(t.is_alive() for t in threads):
                r.load_max = max(r.load_max, os.getloadavg()[0])
                done = len(r.ended)
                if not killed and done >= 0.2 * n_jobs:
                    r.kill_a_worker_child()
                    killed = True
                if not restarted and done >= 0.5 * n_jobs:
                    _redis_shutdown(redis_port)
                    redis.wait(timeout=10)
                    r.note("redis-server shut down (SHUTDOWN NOSAVE)")
                    time.sleep(3)
                    redis = start_redis(redis_port, tmp)
                    r.note("redis-server started again (empty)")
                    restarted = True
                time.sleep(0.1)
            wall = time.perf_counter() - r.t0
            load_end = os.getloadavg()[0]
            records = _all_records(service)
            records.pop(warm["id"], None)
        finally:
            service.stop()
            if redis is not None and redis.poll() is None:
                os.killpg(redis.pid, signal.SIGKILL)
                redis.wait(timeout=10)
    answered = Counter(r.answered)
    states = Counter(rec.state for job_id, rec in records.items() if job_id in answered)
    return {
        "queue": queue,
        "jobs": n_jobs,
        "clients": n_clients,
        "answered": len(answered),
        "records": len(records),
        "succeeded": states.get("succeeded", 0),
        "failed": states.get("failed", 0) + states.get("cancelled", 0),
        "lost": n_jobs - sum(states[s] for s in ENDED),
        "not_submitted": n_jobs - len(answered),
        "duplicated": sum(n - 1 for n in answered.values()) + len(set(records) - set(answered)),
        "reruns": sum(1 for job_id in answered if job_id in records and records[job_id].attempts > 1),
        "attempts": dict(Counter(rec.attempts for rec in records.values())),
        "messages": sorted({rec.message for rec in records.values() if rec.state != "succeeded"}),
        "submit_retries": r.submit_retries,
        "poll_errors": r.poll_errors,
        "errors": r.errors,
        "events": r.events,
        "wall_s": wall,
        "load": (load_start, r.load_max, load_end),
    }


def _all_records(service: Service) -> dict:
    store = service.store()
    out, offset = {}, 0
    while True:
        page, _ = store.list(limit=500, offset=offset)
        if not page:
            return out
        out.update((job.id, job) for job in page)
        offset += len(page)


def _row(f: dict) -> str:
    events = "; ".join(e.split(" s ", 1)[1] + f" at {e.split(' s ', 1)[0].strip()} s" for e in f["events"])
    return (
        f"| {f['queue']} | {f['succeeded']} | {f['failed']} | {f['lost']} | {f['duplicated']} "
        f"| {f['reruns']} | {f['submit_retries']} | {f['wall_s']:.1f} s "
        f"| {f['load'][0]:.1f} / {f['load'][1]:.1f} / {f['load'][2]:.1f} | {events} |"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--queue", choices=["embedded", "redis", "both"], default="both")
    parser.add_argument("--jobs", type=int, default=100)
    parser.add_argument("--clients", type=int, default=10)
    parser.add_argument("--timeout", type=float, default=900)
    parser.add_argument("--no-write", action="store_true", help="print the figures only")
    args = parser.parse_args(argv)
    queues = ["embedded", "redis"] if args.queue == "both" else [args.queue]
    figures = []
    for queue in queues:
        f = run(queue, args.jobs, args.clients, args.timeout)
        print({k: v for k, v in f.items() if k != "events"}, flush=True)
        figures.append(f)
    if not args.no_write:
        params = ", ".join(f"{k}={v}" for k, v in JOB["params"].items())
        write_section(
            "load",
            "\n".join(
                [
                    "## Load with faults (`python -m benchmarks.bench_service_load`)",
                    "",
                    f"`texsynth serve` with 2 worker processes; {args.jobs} `{JOB['method']}` jobs ({params},"
                    f" 48x48 exemplar) from {args.clients} client threads, each submitting its jobs one"
                    " after another (submit, poll until it ends, next; a 503 or refused connection is"
                    " retried). When 20% of the jobs have ended the worker child running a job is"
                    " killed with SIGKILL; on Redis, at 50% redis-server is shut down without saving"
                    " (its queued messages are gone) and started again 3 s later. Counted from the job"
                    " records: lost = submitted but not ended; duplicated = a record no client was"
                    " answered with, or an id answered twice; re-runs = records with more than one"
                    " attempt. Load average: 1-minute, at start / highest / at end.",
                    "",
                    "| queue | succeeded | failed | lost | duplicated | re-runs | submit retries "
                    "| total time | load average | faults |",
                    "|---|---|---|---|---|---|---|---|---|---|",
                    *(_row(f) for f in figures),
                ]
            ),
        )
    ok = all(f["succeeded"] == f["jobs"] and f["duplicated"] == 0 for f in figures)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
