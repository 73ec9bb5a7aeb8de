"""Volume jobs through the service: per-plane uploads, the stack, the slice viewer's endpoint, and the
inputs refused before anything is queued."""

from __future__ import annotations

import io
import json

import httpx
import numpy as np
import pytest
import tifffile
from PIL import Image

from tests.service.conftest import Service, png

pytestmark = pytest.mark.integration


def _planes() -> dict[str, bytes]:
    rng = np.random.default_rng(5)
    return {plane: png((rng.random((24, 32)) * 255).astype(np.uint8)) for plane in ("xy", "xz", "yz")}


def _wait(service: Service, job_id: str) -> dict:
    return service.client().wait(job_id, timeout=120)


def test_volume_job_from_per_plane_exemplars(embedded):
    client = embedded.client()
    planes = _planes()
    job = client.submit(
        method="test-stack", exemplars=planes, params={"width": 20, "height": 16, "depth": 12}, seed=3
    )
    final = _wait(embedded, job["id"])
    assert final["state"] == "succeeded", final["message"]
    assert set(final["inputs"]) == {"exemplar_xy", "exemplar_xz", "exemplar_yz"}
    for name in ("output.tiff", "slices.png", "cube.png", "metrics.json"):
        assert name in final["artifacts"]
    stack = tifffile.imread(io.BytesIO(client.artifact(final, "output.tiff")))
    assert stack.shape == (12, 16, 20)
    # the slice viewer's endpoint: slice 5 of each plane, as the stack has it (8-bit)
    for plane, take in (("xy", lambda v: v[5]), ("xz", lambda v: v[:, 5]), ("yz", lambda v: v[:, :, 5])):
        r = httpx.get(f"{embedded.url}/api/jobs/{job['id']}/slices/{plane}/5.png", timeout=30)
        assert r.status_code == 200 and r.headers["content-type"] == "image/png"
        got = np.asarray(Image.open(io.BytesIO(r.content)))
        want = np.round(take(stack.astype(np.float64)) / 65535 * 255)
        assert np.abs(got.astype(np.float64) - want).max() <= 1
    r = httpx.get(f"{embedded.url}/api/jobs/{job['id']}/slices/xz/16.png", timeout=30)
    assert r.status_code == 422 and "index must lie in [0, 15]" in r.json()["message"]
    r = httpx.get(f"{embedded.url}/api/jobs/{job['id']}/slices/zz/1.png", timeout=30)
    assert r.status_code == 422 and "plane must be one of xy, xz, yz" in r.json()["message"]


@pytest.mark.parametrize(
    ("files", "params", "field", "detail"),
    [
        ({"exemplar_xy": "8"}, {}, "exemplar_xz", "per-plane exemplars come as all three"),
        ({"exemplar_xy": "8", "exemplar_xz": "8", "exemplar_yz": "16"}, {}, "exemplar_xy", "one bit depth"),
        ({"exemplar": "8", "exemplar_xy": "8"}, {}, "exemplar_xy", "takes one exemplar, not one per plane"),
        ({"exemplar": "8"}, {"depth": 4}, "depth", r"each side must lie in [8, 8192]"),
        ({"exemplar": "8"}, {"depth": 512, "width": 512, "height": 1024}, "width", "more than the limit"),
    ],
)
def test_bad_volume_inputs_are_refused_before_queueing(embedded, files, params, field, detail):
    eight = png(np.full((24, 32), 100, np.uint8))
    sixteen = png(np.full((24, 32), 30000, np.uint16))
    method = "test-blur" if "exemplar" in files and "exemplar_xy" in files else "test-stack"
    body = {
        role: (f"{role}.png", eight if depth == "8" else sixteen, "image/png")
        for role, depth in files.items()
    }
    store = embedded.store()
    before = store.count()
    r = httpx.post(
        f"{embedded.url}/api/jobs",
        files=body,
        data={"method": method, "params": json.dumps(params)},
        timeout=30,
    )
    assert r.status_code == 422, r.text
    assert r.json()["field"] == field and detail in r.json()["message"]
    assert store.count() == before


def test_methods_list_their_inputs(embedded):
    methods = {m["name"]: m for m in embedded.client().methods()}
    assert methods["test-stack"]["inputs"] == {
        "exemplar": "alternative",
        "exemplar_xy": "alternative",
        "exemplar_xz": "alternative",
        "exemplar_yz": "alternative",
    }
    assert methods["test-blur"]["inputs"] == {"exemplar": "required", "constraint": "optional"}
    assert "depth" in methods["test-stack"]["size_schema"]["properties"]
