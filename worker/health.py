"""A worker container's health check: ``python -m texsynth.worker.health`` exits 0 when a worker main process
of this host has reported its heartbeat (every 2 s, :mod:`texsynth.worker.celery_app`) within the last 30 s,
else 1 with a one-line reason. docker-compose runs it; the API's own health check cannot see a dead worker
container, only count the live ones."""

from __future__ import annotations

import sys

from texsynth.jobs.config import Settings

#: A worker that has not reported for this long is unhealthy (15 missed heartbeats).
FRESH_SECONDS = 30.0


def main() -> int:
    settings = Settings.from_env()
    store = settings.open_store()
    mine = [w for w in store.workers(fresh_within=FRESH_SECONDS) if w["host"] == store.host]
    if not mine:
        print(f"no worker of {store.host} reported within {FRESH_SECONDS:.0f} s", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
