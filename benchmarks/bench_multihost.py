"""Several hosts, no shared disk: one API and two workers as separate processes, each with its own
private data directory, sharing only Redis, PostgreSQL and an S3 store; faults on all three kinds.

``python -m benchmarks.bench_multihost [--jobs 100] [--clients 10] [--no-write]`` starts a
redis-server, a throwaway PostgreSQL cluster and SeaweedFS's S3 gateway (tests/servers.py), then
``texsynth serve --no-worker`` and two ``texsynth worker`` processes (1 process each), every one
with ``TEXSYNTH_DATABASE_URL``, ``TEXSYNTH_STORAGE_URL`` and its own ``--data-dir``. 10 client threads
submit ``random-phase`` 64x64 jobs one after another (submit, poll until it ends, next; 502/503/504
and refused connections retried). Faults, by jobs ended: at 20% kill -9 the whole worker (main
process and children) that runs a job, started again 5 s later; at 40% PostgreSQL restarted
(``pg_ctl restart -m fast``: every connection cut); at 60% the S3 server stopped for 20 s. Then:
every job's record (succeeded, lost, duplicated as in bench_service_load), every artifact downloaded
through the API, exactly one run's objects per job in the store, and no job file on the API's disk.
Then, without faults, the throughput of 1 and of 2 workers. Writes the "multihost" section of
docs/benchmarks.md; exits 1 unless every job succeeded exactly once and every artifact downloads.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

from benchmarks._report import write_section
from benchmarks.bench_service_load import exemplar_png
from tests.servers import Postgres, SeaweedS3
from tests.service.conftest import REPO, Service, free_port, start_redis, wait_until
from texsynth.app.client import Client, Retry, ServiceError
from texsynth.jobs.store import JobStore

JOB = {"method": "random-phase", "params": {"width": 64, "height": 64}}
ENDED = ("succeeded", "failed", "cancelled")


class Worker:
    """One ``texsynth worker`` in its own process group and its own data directory."""

    def __init__(self, name: str, data_dir: Path, env: dict[str, str]) -> None:
        self.name, self.data_dir, self.env = name, data_dir, env
        self.proc: subprocess.Popen | None = None

    def start(self) -> None:
        code = "import sys; from texsynth.synth.cli import main; sys.exit(main())"
        args = [sys.executable, "-c", code, "worker"]
        args += ["--data-dir", str(self.data_dir), "--concurrency", "1", "--name", f"{self.name}@bench"]
        log = open(self.data_dir.parent / f"{self.name}.log", "ab")  # noqa: SIM115 (the child keeps it)
        self.proc = subprocess.Popen(
            args, env=self.env, cwd=REPO, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
        log.close()

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(10)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGTERM)
            try:
                self.proc.wait(40)
            except subprocess.TimeoutExpired:
                self.kill()

    def pids(self) -> set[int]:
        if self.proc is None or self.proc.poll() is not None:
            return set()
        found = set()
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                with contextlib.suppress(OSError):
                    if os.getpgid(int(entry.name)) == self.proc.pid:
                        found.add(int(entry.name))
        return found


class Cluster:
    """Redis, PostgreSQL, S3, an API and workers, each process with its own folder under ``root``."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.redis_port = free_port()
        self.redis = start_redis(self.redis_port, root)
        self.pg = Postgres().start()
        try:
            self.s3 = SeaweedS3(root / "seaweed").start()
        except BaseException:  # nothing of this run may outlive it
            self.pg.cleanup()
            os.killpg(self.redis.pid, signal.SIGKILL)
            raise
        self.database = self.pg.create_database("texsynth")
        self.env = {
            **os.environ,
            "PYTHONPATH": str(REPO),
            "REDIS_URL": f"redis://127.0.0.1:{self.redis_port}/0",
            "TEXSYNTH_DATABASE_URL": self.database,
            "TEXSYNTH_STORAGE_URL": f"s3://{self.s3.bucket}/bench",
            "TEXSYNTH_STALE_SECONDS": "10",
            **self.s3.env(),
        }
        for folder in ("api", "worker-1", "worker-2"):
            (root / folder / "data").mkdir(parents=True)
        self.api = Service(root / "api" / "data", self.env, worker=False)
        self._store: JobStore | None = None
        self.workers = [Worker(f"worker-{i}", root / f"worker-{i}" / "data", self.env) for i in (1, 2)]

    def store(self) -> JobStore:
        """The job records (read by this script; the files it reads through the API)."""
        if self._store is None:
            self._store = JobStore(self.database, self.root / "reader-jobs")
        return self._store

    def stop(self) -> None:
        for worker in self.workers:
            worker.stop()
        self.api.stop()
        self.s3.stop()
        self.pg.cleanup()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.redis.pid, signal.SIGKILL)
        self.redis.wait(10)


class Clients:
    """``n_clients`` threads submitting ``n_jobs`` jobs one after another; what they were answered."""

    def __init__(self, url: str, exemplar: bytes, n_jobs: int, n_clients: int, seed0: int = 0) -> None:
        self.url, self.exemplar, self.n_jobs, self.n_clients, self.seed0 = (
            url,
            exemplar,
            n_jobs,
            n_clients,
            seed0,
        )
        self.lock = threading.Lock()
        self.answered: list[str] = []
        self.ended: dict[str, str] = {}
        self.submit_retries = 0
        self.errors: list[str] = []
        self.threads = [threading.Thread(target=self.loop, args=(i,), daemon=True) for i in range(n_clients)]

    def loop(self, index: int) -> None:
        client = Client(self.url, timeout=120, retry=Retry(attempts=1))
        for seed in range(index, self.n_jobs, self.n_clients):
            job = None
            while job is None:
                try:
                    job = client.submit(
                        self.exemplar, method=JOB["method"], params=JOB["params"], seed=self.seed0 + seed
                    )
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
            while True:
                try:
                    state = client.job(job["id"])["state"]
                except (ServiceError, OSError):
                    state = None
                if state in ENDED:
                    with self.lock:
                        self.ended[job["id"]] = state
                    break
                time.sleep(0.2)

    def start(self) -> None:
        for thread in self.threads:
            thread.start()

    def alive(self) -> bool:
        return any(thread.is_alive() for thread in self.threads)


def _records(store: JobStore) -> dict:
    out, offset = {}, 0
    while True:
        page, _ = store.list(limit=500, offset=offset)
        if not page:
            return out
        out.update((job.id, job) for job in page)
        offset += len(page)


def _files(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.is_file()] if folder.exists() else []


def faulted_run(cluster: Cluster, exemplar: bytes, n_jobs: int, n_clients: int, before: set[str]) -> dict:
    """The faulted run; ``before``: ids of the jobs that existed already (the warm-up)."""
    events: list[str] = []
    t0 = time.perf_counter()

    def note(text: str) -> None:
        events.append(f"{time.perf_counter() - t0:5.1f} s {text}")
        print(events[-1], flush=True)

    clients = Clients(cluster.api.url, exemplar, n_jobs, n_clients, seed0=1000)
    load = [os.getloadavg()[0]]
    clients.start()
    store = cluster.store()
    step, restart_worker_at, s3_back_at = 0, None, None
    while clients.alive():
        load.append(os.getloadavg()[0])
        done = len(clients.ended)
        if step == 0 and done >= 0.2 * n_jobs:
            running = {j.pid: j.id for j in store.active() if j.state == "running" and j.pid}
            victim = next((w for w in cluster.workers if w.pids() & set(running)), cluster.workers[0])
            held = [running[pid] for pid in victim.pids() & set(running)]
            victim.kill()
            note(f"kill -9 {victim.name} ({'running job ' + held[0][:8] if held else 'idle'})")
            restart_worker_at, step = time.monotonic() + 5, 1
        if restart_worker_at and time.monotonic() >= restart_worker_at:
            victim.start()
            note(f"{victim.name} started again")
            restart_worker_at = None
        if step == 1 and done >= 0.4 * n_jobs:
            note("PostgreSQL restart (pg_ctl restart -m fast)")
            cluster.pg.restart()
            note("PostgreSQL up again")
            step = 2
        if step == 2 and done >= 0.6 * n_jobs:
            cluster.s3.stop()
            note("S3 server stopped")
            s3_back_at, step = time.monotonic() + 20, 3
        if s3_back_at and time.monotonic() >= s3_back_at:
            note("S3 server starting again (20 s after its stop)")
            cluster.s3.start()
            note("S3 server answering again")
            s3_back_at = None
        time.sleep(0.2)
    wall = time.perf_counter() - t0
    records = {k: v for k, v in _records(store).items() if k in set(clients.answered)}
    answered = Counter(clients.answered)
    states = Counter(rec.state for rec in records.values())
    # every artifact through the API; exactly one run's objects per job in the store
    client = Client(cluster.api.url, timeout=60)
    downloads = failures = 0
    stray_runs = 0
    for job_id in answered:
        job = client.job(job_id)
        for name in job["artifacts"]:
            try:
                downloads += bool(client.artifact(job, name))
            except (ServiceError, OSError):
                failures += 1
        runs = {k.split("/runs/")[1].split("/")[0] for k in cluster.s3.keys(f"bench/jobs/{job_id}/runs/")}
        stray_runs += len(runs - {records[job_id].artifacts_run})
    api_files = _files(cluster.api.data_dir / "jobs") + _files(cluster.api.data_dir / "scratch")
    return {
        "jobs": n_jobs,
        "succeeded": states.get("succeeded", 0),
        "failed": states.get("failed", 0) + states.get("cancelled", 0),
        "lost": n_jobs - sum(states[s] for s in ENDED),
        "duplicated": sum(n - 1 for n in answered.values())
        + len(set(_records(store)) - set(answered) - before),
        "reruns": sum(1 for rec in records.values() if rec.attempts > 1),
        "submit_retries": clients.submit_retries,
        "errors": clients.errors,
        "downloads": downloads,
        "download_failures": failures,
        "stray_runs": stray_runs,
        "api_files": len(api_files),
        "events": events,
        "wall_s": wall,
        "load": (load[0], max(load), os.getloadavg()[0]),
    }


def throughput(
    cluster: Cluster, exemplar: bytes, workers: int, n_jobs: int, n_clients: int, seed0: int
) -> dict:
    for worker in cluster.workers[workers:]:
        worker.stop()
    for worker in cluster.workers[:workers]:
        if worker.proc is None or worker.proc.poll() is not None:
            worker.start()
    store = cluster.store()
    wait_until(lambda: len(store.workers(fresh_within=5)) == workers, 120, 0.5, f"{workers} live worker(s)")
    clients = Clients(cluster.api.url, exemplar, n_jobs, n_clients, seed0=seed0)
    load = [os.getloadavg()[0]]
    t0 = time.perf_counter()
    clients.start()
    while clients.alive():
        load.append(os.getloadavg()[0])
        time.sleep(0.2)
    wall = time.perf_counter() - t0
    ok = sum(1 for state in clients.ended.values() if state == "succeeded")
    return {
        "workers": workers,
        "jobs": n_jobs,
        "succeeded": ok,
        "wall_s": wall,
        "per_min": 60 * ok / wall,
        "load": (load[0], max(load), os.getloadavg()[0]),
    }


def _section(f: dict, rates: list[dict], args: argparse.Namespace) -> str:
    events = "; ".join(e.split(" s ", 1)[1] + f" at {e.split(' s ', 1)[0].strip()} s" for e in f["events"])
    load = f"{f['load'][0]:.1f} / {f['load'][1]:.1f} / {f['load'][2]:.1f}"
    text = (
        "One API (`texsynth serve --no-worker`) and two workers (`texsynth worker --concurrency 1`)"
        " as separate processes, each with its own private data directory, sharing only Redis,"
        " PostgreSQL (`TEXSYNTH_DATABASE_URL`) and an S3 store (SeaweedFS, `TEXSYNTH_STORAGE_URL`);"
        f" all on this machine, as three hosts would run them. {f['jobs']} `{JOB['method']}` 64x64"
        f" jobs from {args.clients} client threads (submit, poll until it ends, next; 502/503/504"
        " retried). Faults by jobs ended: 20% kill -9 of the worker running a job (its main process"
        " and children; started again 5 s later), 40% PostgreSQL restarted, 60% the S3 server"
        " stopped for 20 s. Lost, duplicated and re-runs as in the load run above; downloads: every"
        " artifact of every job fetched through the API; stray runs: objects of a run other than"
        " the committed one; API files: files under the API's data directory's `jobs/` and `scratch/`."
    )
    return "\n".join(
        [
            "## Several hosts, no shared disk (`python -m benchmarks.bench_multihost`)",
            "",
            text,
            "",
            "| succeeded | failed | lost | duplicated | re-runs | submit retries | artifacts downloaded"
            " | download failures | stray runs | API files | total time | load average | faults |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
            f"| {f['succeeded']} | {f['failed']} | {f['lost']} | {f['duplicated']} | {f['reruns']}"
            f" | {f['submit_retries']} | {f['downloads']} | {f['download_failures']}"
            f" | {f['stray_runs']} | {f['api_files']} | {f['wall_s']:.1f} s | {load} | {events} |",
            "",
            f"Throughput without faults ({args.throughput_jobs} jobs, {args.clients} clients, the"
            " same servers):",
            "",
            "| workers | succeeded | total time | jobs per minute | load average |",
            "|---|---|---|---|---|",
            *(
                f"| {r['workers']} | {r['succeeded']} | {r['wall_s']:.1f} s | {r['per_min']:.1f}"
                f" | {r['load'][0]:.1f} / {r['load'][1]:.1f} / {r['load'][2]:.1f} |"
                for r in rates
            ),
        ]
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=100)
    parser.add_argument("--clients", type=int, default=10)
    parser.add_argument("--throughput-jobs", type=int, default=60)
    parser.add_argument("--no-write", action="store_true", help="print the figures only")
    args = parser.parse_args(argv)
    exemplar = exemplar_png()
    with tempfile.TemporaryDirectory(prefix="texsynth-multihost-") as tmp:
        cluster = Cluster(Path(tmp))
        try:
            cluster.api.start(timeout=120)
            for worker in cluster.workers:
                worker.start()
            client = cluster.api.client()
            wait_until(lambda: len(cluster.store().workers(fresh_within=5)) == 2, 120, 0.5, "2 workers")
            warm = set()
            for seed in range(2):  # warm both: numba kernels from the cache, imports
                job = client.submit(exemplar, method=JOB["method"], params=JOB["params"], seed=seed)
                client.wait(job["id"], timeout=300)
                warm.add(job["id"])
            faults = faulted_run(cluster, exemplar, args.jobs, args.clients, warm)
            print({k: v for k, v in faults.items() if k != "events"}, flush=True)
            rates = [
                throughput(cluster, exemplar, n, args.throughput_jobs, args.clients, 5000 + 1000 * n)
                for n in (1, 2)
            ]
            print(rates, flush=True)
        finally:
            cluster.stop()
    if not args.no_write:
        write_section("multihost", _section(faults, rates, args))
    ok = (
        faults["succeeded"] == faults["jobs"]
        and faults["duplicated"] == 0
        and faults["download_failures"] == 0
        and faults["api_files"] == 0
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
