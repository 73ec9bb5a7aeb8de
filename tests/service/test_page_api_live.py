"""The page's contract against a real ``texsynth serve`` and worker (issue 27): every registered method
runs from the defaults its schema declares, as the form sends them; results carry verdicts, the
exemplar's tensor images and fringe statistics only for fringes; a volume's voxel size reaches its TIFF;
a cancelled job stays below 100 %."""

from __future__ import annotations

import io
import json
import time
import zipfile

import httpx
import numpy as np
import pytest
import tifffile
from PIL import Image

from tests.service.conftest import png, wait_until
from texsynth.synth.api import available_methods

pytestmark = pytest.mark.integration


def _example(service, name: str, side: int = 48) -> bytes:
    """A bundled example from the service, its top-left ``side`` px (small runs)."""
    r = httpx.get(f"{service.url}/api/examples/{name}", timeout=30)
    assert r.status_code == 200
    return png(np.asarray(Image.open(io.BytesIO(r.content)))[:side, :side])


def _defaults(schema: dict) -> dict:
    """Every parameter at the default its schema declares: what the form sends untouched."""
    return {name: prop.get("default") for name, prop in schema["properties"].items()}


def _post(service, data: dict, files: dict) -> httpx.Response:
    return httpx.post(f"{service.url}/api/jobs", data=data, files=files, timeout=60)


@pytest.mark.parametrize("name", sorted(available_methods()))
def test_every_method_runs_from_its_declared_defaults(embedded, name):
    methods = {m["name"]: m for m in httpx.get(f"{embedded.url}/api/methods", timeout=30).json()["data"]}
    method = methods[name]
    volume = method["output_ndim"] == 3
    side = 16 if volume else 48
    size = {"width": side, "height": side, **({"depth": side} if volume else {})}
    files = {"exemplar": ("soot.png", _example(embedded, "soot-fringes", 64))}
    if method["constraint"] != "none":
        files["constraint"] = ("waves.png", _example(embedded, "constraint-waves"))
    data = {"method": name, "params": json.dumps(_defaults(method["params_schema"])), "seed": "1"}
    r = _post(embedded, {**data, **{k: str(v) for k, v in size.items()}}, files)
    assert r.status_code == 202, r.text
    job = embedded.client().wait(r.json()["id"], timeout=300)
    assert job["state"] == "succeeded", job["message"]
    assert {"exemplar-coherence.png", "exemplar-orientation.png", "output.png"} <= set(job["artifacts"])
    metrics = job["metrics"]
    assert metrics["fringes"]["shown"] is True  # soot has lattice fringes: their statistics, both sides
    assert metrics["fringes"]["presence"]["count"] > 0
    if not volume:  # a volume's fringe statistics are per axis
        assert "mean_length" in metrics["fringes"]["exemplar"]
    headline = metrics["headline"]
    assert {"grey_kl", "orientation_kl", "log_euclidean"} <= set(headline)
    for entry in headline.values():
        assert entry["verdict"] in ("meets", "near", "misses") and entry["target"] is not None
        assert entry["direction"] in ("lower", "abs-lower", "near-1", "higher")
    assert "stationarity" in metrics["exemplar"]  # the exemplar's stationarity (and any warning) stays


def test_a_brick_job_shows_no_fringe_statistics_and_zips_its_artifacts(embedded):
    data = {"method": "quilting", "width": "64", "height": "64", "seed": "2"}
    r = _post(embedded, data, {"exemplar": ("brick.png", _example(embedded, "brick", 128))})
    job = embedded.client().wait(r.json()["id"], timeout=120)
    assert job["state"] == "succeeded", job["message"]
    fringes = job["metrics"]["fringes"]
    assert fringes["shown"] is False and "fringe" in fringes["reason"]
    assert "fringe_ks_length" not in job["metrics"]["headline"]
    assert "fringe_ks_length" not in job["metrics"]["summary"]
    assert not any(name.startswith("plots/fringe") for name in job["artifacts"])
    assert job["exemplar_name"] == "brick.png"
    listed = httpx.get(f"{embedded.url}/api/jobs", params={"method": "quilting"}, timeout=30).json()
    assert job["id"] in [j["id"] for j in listed["data"]]
    r = httpx.get(embedded.url + job["artifacts_zip"], timeout=60)
    with zipfile.ZipFile(io.BytesIO(r.content)) as archive:
        assert sorted(archive.namelist()) == sorted(f"{job['id']}/{n}" for n in job["artifacts"])
    thumb = httpx.get(embedded.url + job["thumbnail"], timeout=30)
    assert thumb.status_code == 200 and Image.open(io.BytesIO(thumb.content)).size == (64, 64)


@pytest.mark.parametrize(
    ("voxel", "spacing", "unit"), [({"voxel_size": "0.055"}, 0.055, "nm"), ({}, None, None)]
)
def test_a_volumes_voxel_size_reaches_its_tiff(embedded, voxel, spacing, unit):
    data = {"method": "solid-kopf", "width": "16", "height": "16", "depth": "12", "seed": "1", **voxel}
    r = _post(embedded, data, {"exemplar": ("soot.png", _example(embedded, "soot-fringes"))})
    assert r.status_code == 202, r.text
    job = embedded.client().wait(r.json()["id"], timeout=300)
    assert job["state"] == "succeeded", job["message"]
    stack = httpx.get(embedded.url + job["artifacts"]["output.tiff"], timeout=60).content
    with tifffile.TiffFile(io.BytesIO(stack)) as tif:
        meta = tif.imagej_metadata or {}
        assert tif.asarray().shape == (12, 16, 16)
        if spacing is None:  # uncalibrated: no spacing, no unit
            assert "spacing" not in meta and "unit" not in meta
        else:
            assert meta["spacing"] == pytest.approx(spacing) and meta["unit"] == unit
            x_resolution = tif.pages[0].resolution[0]
            assert x_resolution == pytest.approx(1 / spacing, rel=1e-4)
    manifest = json.loads(httpx.get(embedded.url + job["artifacts"]["manifest.json"], timeout=30).content)
    assert manifest.get("voxel_size") == (spacing and pytest.approx(spacing))
    assert (job["voxel_size"], job["voxel_unit"]) == (spacing, unit)


def test_a_cancelled_job_keeps_its_progress(embedded):
    data = {"method": "test-blur", "params": json.dumps({"steps": 200, "delay": 0.05}), "seed": "1"}
    r = _post(embedded, data, {"exemplar": ("e.png", _example(embedded, "grass", 32))})
    job_id = r.json()["id"]
    url = f"{embedded.url}/api/jobs/{job_id}"
    wait_until(lambda: httpx.get(url, timeout=10).json()["fraction"] > 0.1, 60, 0.2, "progress")
    assert httpx.delete(url, timeout=10).status_code == 202
    deadline = time.monotonic() + 30
    while (job := httpx.get(url, timeout=10).json())["state"] != "cancelled" and time.monotonic() < deadline:
        time.sleep(0.2)
    assert job["state"] == "cancelled" and 0.1 < job["fraction"] < 0.9, job
