"""The service with its state off the machine: job records in PostgreSQL, files in an S3 store
(real servers), as on several hosts. The API's data directory never holds a job's file."""

from __future__ import annotations

import httpx
import pytest

from tests.service.conftest import Service

pytestmark = [pytest.mark.integration, pytest.mark.slow]


@pytest.fixture
def cluster_service(tmp_path, pg_url, s3_url, seaweed):
    env = {
        "TEXSYNTH_DATABASE_URL": pg_url,
        "TEXSYNTH_STORAGE_URL": s3_url,
        **seaweed.env(),
    }
    service = Service(tmp_path / "data", env, concurrency=1).start(timeout=120)
    yield service
    service.stop()


def test_a_job_runs_with_records_in_postgres_and_files_in_s3(cluster_service, seaweed, s3_url, exemplar_png):
    client = cluster_service.client()
    job = client.submit(exemplar_png, method="test-blur", params={"width": 32, "height": 32, "steps": 3})
    final = client.wait(job["id"], timeout=120, poll=0.3)
    assert final["state"] == "succeeded", final
    prefix = s3_url.split("/", 3)[3] + f"/jobs/{job['id']}/"
    keys = seaweed.keys(prefix)
    assert f"{prefix}inputs/exemplar.png" in keys and f"{prefix}manifest.json" in keys
    for name in final["artifacts"]:
        data = client.artifact(final, name)
        assert data
        run_keys = [k for k in keys if k.startswith(f"{prefix}runs/") and k.endswith(f"/{name}")]
        assert len(run_keys) == 1, (name, keys)  # one run's upload, the one the record names
        body = seaweed.client().get_object(Bucket=seaweed.bucket, Key=run_keys[0])["Body"].read()
        assert body == data
    answer = httpx.get(cluster_service.url + final["inputs"]["exemplar"])
    assert answer.status_code == 200 and answer.content == exemplar_png
    assert answer.headers["content-type"] == "image/png"
    # the API's (and, here, the worker's) data directory: no job folder, an empty scratch
    jobs_dir = cluster_service.data_dir / "jobs"
    assert not jobs_dir.exists() or not any(jobs_dir.iterdir())
    assert not any((cluster_service.data_dir / "scratch").glob("*"))
    assert not (cluster_service.data_dir / "jobs.sqlite").exists()
    # a missing artifact is 404, another job's id too
    assert httpx.get(f"{cluster_service.url}/api/jobs/{job['id']}/artifacts/nothing.png").status_code == 404
    # DELETE removes the objects
    assert httpx.delete(f"{cluster_service.url}/api/jobs/{job['id']}").status_code == 200
    assert not seaweed.keys(prefix)
