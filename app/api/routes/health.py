"""``/api/health``: is the API up, the broker reachable, a worker alive?"""

from __future__ import annotations

import shutil
import time

from fastapi import APIRouter, Response

from texsynth.app.api.deps import ServiceDep
from texsynth.app.errors import disk_full
from texsynth.app.schemas import HealthPublic
from texsynth.app.service import Service
from texsynth.jobs.broker import SCHEME
from texsynth.jobs.reaper import stranded

router = APIRouter(prefix="/api/health", tags=["health"])


@router.get("", response_model=HealthPublic, responses={503: {"model": HealthPublic}})
def health(service: ServiceDep, response: Response) -> dict:
    """``200`` when API, broker and at least one worker are up; ``503`` naming what is missing."""
    broker = service.broker_ok()
    problems = disk_problems(service)
    try:
        workers = [w["name"] for w in service.store.workers(fresh_within=10.0)]
        _, queued = service.store.list(state="queued", limit=1)
        _, running = service.store.list(state="running", limit=1)
        waiting = stranded(service.store, service.settings)
    except Exception as exc:
        if not disk_full(exc):
            raise
        problems.append("the job records cannot be read: the disk is full")
        workers, queued, running, waiting = [], 0, 0, []
    if waiting:
        problems.append(
            f"{len(waiting)} queued job(s) not received by any worker although workers are idle; "
            "the reaper sends them again"
        )
    if not service.store.storage.ok():
        problems.append("the object store is unreachable (check TEXSYNTH_STORAGE_URL and AWS_*)")
    if not broker:
        problems.append("the broker is unreachable (check REDIS_URL / the data directory)")
    if not workers:
        problems.append("no worker is running (start one with `texsynth worker`)")
    if not broker or not workers:
        response.status_code = 503
    url = service.settings.redis_url or f"{SCHEME}:// (embedded, in the data directory)"
    return {
        "status": "ok" if not problems else "degraded",
        "api": True,
        "broker": broker,
        "broker_url": _redact(url),
        "workers": workers,
        "queued": queued,
        "running": running,
        "message": "; ".join(problems) or "ready",
    }


#: Seconds ``degraded`` is reported after a write failed for lack of room.
FULL_DISK_MEMORY = 60.0


def disk_problems(service: Service) -> list[str]:
    """What health says about the data directory's disk: nearly full (less free than one largest
    upload), or a write that failed for lack of room within the last minute."""
    try:
        free = shutil.disk_usage(service.settings.data_dir).free
    except OSError:
        free = None
    if free is not None and free < service.settings.max_body_bytes:
        return [
            f"the data directory's disk is nearly full ({free / 2**20:.1f} MiB free): new jobs are "
            "refused (507) until room is made"
        ]
    if service.disk_full_at is not None and time.time() - service.disk_full_at < FULL_DISK_MEMORY:
        return ["a write failed in the last minute because the data directory's disk was full"]
    return []


def _redact(url: str) -> str:
    if "@" in url and "://" in url:
        scheme, rest = url.split("://", 1)
        return f"{scheme}://***@{rest.split('@', 1)[1]}"
    return url
