"""A client generated from the service's OpenAPI document does the main tasks (issue 29).

``openapi-python-client`` (a dev dependency) generates a package from a running token service's
``/openapi.json`` with docs/openapi-python-client.yaml, with every proxy pointed at a closed port so
that any download at generation time fails; the generated client then submits a job with a typed
per-method parameter model, follows it to the end and downloads its PNG, TIFF and JSON artifacts.
"""

from __future__ import annotations

import importlib
import io
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.service.conftest import REPO, TOKENS

pytestmark = [pytest.mark.integration, pytest.mark.slow]

PACKAGE = "texsynth_api_client"


@pytest.fixture(scope="module")
def generated(token_service, tmp_path_factory):
    """The generated package, imported (removed from ``sys.modules`` afterwards)."""
    import httpx

    folder = tmp_path_factory.mktemp("generated")
    spec = folder / "openapi.json"
    spec.write_bytes(httpx.get(f"{token_service.url}/openapi.json", timeout=30).content)
    exe = shutil.which("openapi-python-client", path=str(Path(sys.executable).parent))
    assert exe is not None, "openapi-python-client is a dev dependency: pip install -e '.[dev]'"
    closed = "http://127.0.0.1:9"  # offline: a template fetched at run time would fail here
    env = {**os.environ, "HTTP_PROXY": closed, "HTTPS_PROXY": closed, "ALL_PROXY": closed, "NO_PROXY": ""}
    done = subprocess.run(
        [exe, "generate", "--path", str(spec), "--config", str(REPO / "docs" / "openapi-python-client.yaml")],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Warning" not in done.stdout + done.stderr, done.stdout + done.stderr  # nothing left out
    sys.path.insert(0, str(folder / "texsynth-api-client"))
    try:
        yield importlib.import_module(PACKAGE)
    finally:
        sys.path.remove(str(folder / "texsynth-api-client"))
        for name in [n for n in sys.modules if n == PACKAGE or n.startswith(PACKAGE + ".")]:
            del sys.modules[name]


def test_a_generated_client_submits_waits_and_downloads(generated, token_service, exemplar_png):
    client_mod = importlib.import_module(f"{PACKAGE}.client")
    types = importlib.import_module(f"{PACKAGE}.types")
    models = importlib.import_module(f"{PACKAGE}.models")
    submit = importlib.import_module(f"{PACKAGE}.api.jobs.submit_job_api_jobs_post")
    get_job = importlib.import_module(f"{PACKAGE}.api.jobs.get_job_api_jobs_job_id_get")
    get_artifact = importlib.import_module(
        f"{PACKAGE}.api.jobs.get_artifact_api_jobs_job_id_artifacts_name_get"
    )

    client = client_mod.AuthenticatedClient(base_url=token_service.url, token=TOKENS["alice"], timeout=30)
    params = models.RandomPhaseParams(periodic=True)  # the method's parameters, typed, from the schema
    body = models.BodySubmitJobApiJobsPost(
        method=models.MethodName("random-phase"),
        params=json.dumps(params.to_dict()),
        exemplar=types.File(payload=io.BytesIO(exemplar_png), file_name="fringes.png", mime_type="image/png"),
        width=48,
        height=40,
        seed=3,
    )
    job = submit.sync(client=client, body=body)
    assert isinstance(job, models.JobPublic), job
    assert job.state in (models.JobState.QUEUED, models.JobState.RUNNING)
    assert job.params["periodic"] is True

    deadline = time.monotonic() + 120
    while job.state not in (models.JobState.SUCCEEDED, models.JobState.FAILED, models.JobState.CANCELLED):
        assert time.monotonic() < deadline, f"job still {job.state} after 120 s"
        time.sleep(0.2)
        job = get_job.sync(job.id, client=client)
        assert isinstance(job, models.JobPublic), job
    assert job.state == models.JobState.SUCCEEDED, job.message

    png = get_artifact.sync(job_id=job.id, name="output.png", client=client)
    assert isinstance(png, types.File), png
    image = np.asarray(Image.open(png.payload))
    assert image.shape == (40, 48) and image.dtype == np.uint8 and image.std() > 0
    tiff = get_artifact.sync(job_id=job.id, name="output.tiff", client=client)
    assert isinstance(tiff, types.File) and tiff.payload.read(4) in (b"II*\x00", b"MM\x00*")
    metrics = get_artifact.sync(job_id=job.id, name="metrics.json", client=client)
    assert "grey" in json.loads(metrics.payload.read())["metrics"]

    client.get_httpx_client().close()
    with client_mod.Client(base_url=token_service.url, timeout=30) as anonymous:
        refused = get_job.sync_detailed(job.id, client=anonymous)
    assert refused.status_code == 401 and isinstance(refused.parsed, models.ErrorPublic)
