"""What the browser page reads from the API (issue 27), in process: parameter schemas made for a short
form, one-line 422s per field, the favicon, examples, job lists with thumbnails, the artifacts' zip."""

from __future__ import annotations

import io
import json
import os
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tests.service.test_tokens import _client
from texsynth.jobs.config import Settings
from texsynth.synth.api import available_methods
from texsynth.synth.params import BOUNDS

#: Words of the papers and the code that a one-sentence help may use only inside brackets, next to the
#: plain words that explain them ("(k, k-coherence search)", "(σ_w)", "(W, Eq. 5)").
JARGON = re.compile(
    r"\b(?:D_M|S_con|O_con|S_en|I_sor|IRLS|SSD|STD|gdist|chamfer|Sigma|mu|eq|Eq|LG|CLG|RCLG|ED|SO|FN|LE)\b"
    r"|k-coheren|_"
)


def _outside_brackets(text: str) -> str:
    depth, out = 0, []
    for char in text:
        depth += char == "("
        if depth == 0:
            out.append(char)
        depth -= char == ")" and depth > 0
    return "".join(out)


def _png(side: int = 32, seed: int = 1) -> bytes:
    buf = io.BytesIO()
    rng = np.random.default_rng(seed)
    Image.fromarray((rng.random((side, side)) * 255).astype(np.uint8)).save(buf, "PNG")
    return buf.getvalue()


@pytest.fixture
def open_api(tmp_path):
    client, service = _client(Settings(data_dir=tmp_path / "data"))
    with client:
        yield client, service


# -- parameter schemas -----------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(available_methods()))
def test_every_method_has_a_short_basic_form_and_plain_help(name):
    spec = available_methods()[name]
    props = spec.schema()["properties"]
    basic = [field for field, prop in props.items() if prop.get("x-basic")]
    assert 1 <= len(basic) <= 10, basic
    assert "periodic" in basic
    for field, prop in props.items():
        text = prop.get("description", "")
        assert text and len(text) <= 160, (field, len(text), text)
        assert text[0].isupper() and text.endswith("."), (field, text)
        jargon = JARGON.search(_outside_brackets(text))
        assert jargon is None, (field, jargon and jargon.group(), text)


@pytest.mark.parametrize("name", sorted(available_methods()))
def test_bounds_units_and_odd_are_declared_where_they_apply(name):
    model = available_methods()[name].params_model
    props = model.model_json_schema()["properties"]
    for field, info in model.model_fields.items():
        prop = props[field]
        bounded = any(type(m).__name__ in ("Ge", "Gt", "Le", "Lt") for m in info.metadata)
        assert bounded == any(key in prop for key in BOUNDS), field  # also on optional fields
        if field.endswith(("_size", "patch_size")) and "kset" not in field and field != "patch_size":
            assert prop.get("x-odd") is True, field
        if field in ("neighbourhood_size", "patch_size", "overlap", "angular_step", "sigma_w"):
            assert prop.get("x-unit"), field
    if "neighbourhood_size" in model.model_fields:  # x-odd is checked by the model as well
        with pytest.raises(ValueError, match="odd"):
            model.model_validate({"neighbourhood_size": 12})


def test_list_fields_are_arrays_of_choices():
    prop = available_methods()["solid-kopf"].schema()["properties"]["planes"]
    assert prop["type"] == "array" and prop["items"]["enum"] == ["xy", "xz", "yz"]
    assert prop["default"] == ["xy", "xz", "yz"]


def test_the_api_and_openapi_carry_the_form_hints(open_api):
    client, _ = open_api
    methods = {m["name"]: m for m in client.get("/api/methods").json()["data"]}
    props = methods["tensor-constrained"]["params_schema"]["properties"]
    assert props["p"]["x-basic"] is True and props["p"]["maximum"] == 1.0
    assert "(p, Eq. 13)" in props["p"]["description"]
    assert props["refinement_size"]["x-odd"] is True and props["refinement_size"]["minimum"] == 3
    assert props["refinement_size"]["nullable"] is True
    size = methods["solid-kopf"]["size_schema"]["properties"]
    assert size["depth"]["x-basic"] is True and size["depth"]["x-unit"] == "voxels"
    components = client.get("/openapi.json").json()["components"]["schemas"]
    assert components["TensorConstrainedParams"]["properties"]["p"]["x-basic"] is True


# -- 422: one entry per bad field, one line each -----------------------------------------------------


def test_a_rejected_submit_lists_each_bad_field_in_one_line(open_api):
    client, service = open_api
    params = {"neighbourhood_size": 12, "levels": 99, "k": "many"}
    r = client.post(
        "/api/jobs",
        data={"method": "wei-levoy", "params": json.dumps(params), "width": "32", "height": "32"},
        files={"exemplar": ("e.png", _png())},
    )
    assert r.status_code == 422, r.text
    body = r.json()
    locs = [tuple(item["loc"]) for item in body["detail"]]
    assert sorted(locs) == [("params", "k"), ("params", "levels")]  # the odd check waits for valid fields
    for item in body["detail"]:
        assert "\n" not in item["msg"] and item["type"] and len(item["msg"]) < 160
    assert body["field"] == locs[0][1] and "levels" in body["message"] and "k:" in body["message"]
    assert service.store.count() == 0
    r = client.post(
        "/api/jobs",
        data={"method": "wei-levoy", "params": '{"neighbourhood_size": 12}'},
        files={"exemplar": ("e.png", _png())},
    )
    item = r.json()["detail"][0]
    assert item["loc"] == ["params", "neighbourhood_size"] and item["input"] == 12
    assert item["msg"] == "neighbourhood_size must be odd"
    assert "levels" not in r.text  # never the whole parameter dictionary


def test_a_model_check_names_its_field_not_the_dictionary(open_api):
    client, _ = open_api
    params = {"periodic": True, "iterations": 1, "neighbourhood": "causal", "levels": 1}
    r = client.post(
        "/api/jobs",
        data={"method": "wei-levoy", "params": json.dumps(params)},
        files={"exemplar": ("e.png", _png())},
    )
    item = r.json()["detail"][0]
    assert item["loc"] == ["params", "periodic"] and "iterations >= 2" in item["msg"]
    assert "'levels'" not in item["msg"]


@pytest.mark.parametrize(
    ("data", "loc"),
    [
        ({"method": "wei-levoy", "width": "5"}, ["body", "width"]),
        ({"method": "nope"}, ["body", "method"]),
        ({"method": "wei-levoy", "params": "{oops"}, ["body", "params"]),
    ],
)
def test_form_fields_are_located_in_the_body(open_api, data, loc):
    client, _ = open_api
    r = client.post("/api/jobs", data=data, files={"exemplar": ("e.png", _png())})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == loc, r.text


def test_a_bad_exemplar_and_a_bad_query_have_the_same_shape(open_api):
    client, _ = open_api
    r = client.post("/api/jobs", data={"method": "wei-levoy"}, files={"exemplar": ("e.png", _png()[:60])})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "exemplar"]
    r = client.get("/api/jobs", params={"state": "bogus"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "state"]


# -- favicon -------------------------------------------------------------------------------------------


def test_favicon_is_served_and_linked(open_api):
    client, _ = open_api
    r = client.get("/favicon.ico")
    assert r.status_code == 200 and r.headers["content-type"] == "image/x-icon"
    assert Image.open(io.BytesIO(r.content)).size == (32, 32)
    assert '<link rel="icon" href="/favicon.ico"' in client.get("/").text


# -- examples ------------------------------------------------------------------------------------------


def test_examples_are_listed_served_and_credited(open_api):
    client, _ = open_api
    listed = client.get("/api/examples").json()
    names = [e["name"] for e in listed]
    assert names == ["soot-fringes", "brick", "grass", "gravel", "laminar", "constraint-waves"]
    methods = {m["name"] for m in client.get("/api/methods").json()["data"]}
    for e in listed:
        assert e["licence"] in ("CC0-1.0", "MIT") and e["credit"] and e["title"]
        assert e["kind"] in ("2d", "constraint") and e["suggested_method"] in methods
        image = client.get(e["url"])
        assert image.status_code == 200 and image.headers["content-type"] == "image/png"
        assert Image.open(io.BytesIO(image.content)).size == (128, 128)
        thumb = client.get(e["thumbnail"])
        assert thumb.status_code == 200 and max(Image.open(io.BytesIO(thumb.content)).size) == 96
    fringed = {e["name"] for e in listed if e["has_fringes"]}
    assert fringed == {"soot-fringes", "laminar"}  # brick, grass, gravel: no HRTEM fringe statistics
    assert [e["kind"] for e in listed].count("constraint") == 1
    assert client.get("/api/examples/nope").status_code == 404
    assert client.get("/api/examples/..%2Fmain.py").status_code == 404


def test_examples_are_public_with_tokens(tmp_path):
    client, _ = _client(Settings(data_dir=tmp_path / "data", api_tokens="alice:" + "a" * 20))
    with client:
        assert client.get("/api/jobs").status_code == 401
        assert client.get("/api/examples").status_code == 200
        assert client.get("/api/examples/brick/thumbnail").status_code == 200


def test_the_bundled_examples_are_their_sources_and_packaged():
    from texsynth.app.examples.build import main

    assert main(["--check"]) == 0
    import tomllib

    text = (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text()
    data = tomllib.loads(text)["tool"]["setuptools"]["package-data"]["texsynth.app.examples"]
    assert "*.png" in data and "README.md" in data  # tests/test_packaging.py looks inside a wheel


# -- job list, thumbnails, zip ---------------------------------------------------------------------------


def _submit(client, method="wei-levoy", name="carbon sample.png", **data):
    form = {"method": method, "width": "32", "height": "32", "seed": "1", **data}
    return client.post("/api/jobs", data=form, files={"exemplar": (name, _png(40))})


def _finish(service, job_id: str, side: int = 64) -> None:
    """Run the job as a worker would, without synthesis: claim, write artifacts, commit."""
    token, _ = service.store.claim(job_id, os.getpid(), 10.0)
    staging = service.store.job_dir(job_id) / f".run-{token}"
    (staging / "plots").mkdir(parents=True)
    (staging / "output.png").write_bytes(_png(side, seed=2))
    (staging / "metrics.json").write_text('{"summary": {}}')
    (staging / "plots" / "grey.png").write_bytes(_png(8))
    names = ["output.png", "metrics.json", "plots/grey.png"]
    assert service.store.commit_success(job_id, token, staging, names, {}, {})


def test_the_job_list_filters_pages_and_names_the_exemplar(open_api):
    client, service = open_api
    ids = [_submit(client, name=f"sample-{i}.png").json()["id"] for i in range(3)]
    other = _submit(client, method="quilting", name="C:\\lab\\brick.png").json()["id"]
    _finish(service, ids[0])
    page = client.get("/api/jobs", params={"method": "wei-levoy", "limit": 2}).json()
    assert page["count"] == 3 and [j["id"] for j in page["data"]] == ids[::-1][:2]
    rest = client.get("/api/jobs", params={"method": "wei-levoy", "limit": 2, "offset": 2}).json()
    assert [j["id"] for j in rest["data"]] == [ids[0]]
    done = client.get("/api/jobs", params={"method": "wei-levoy", "state": "succeeded"}).json()
    assert done["count"] == 1 and done["data"][0]["exemplar_name"] == "sample-0.png"
    assert client.get(f"/api/jobs/{other}").json()["exemplar_name"] == "brick.png"
    r = client.get("/api/jobs", params={"method": "nope"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "method"]


def test_thumbnails_show_the_exemplar_then_the_output(open_api):
    client, service = open_api
    job = _submit(client).json()
    r = client.get(job["thumbnail"])
    assert r.status_code == 200 and Image.open(io.BytesIO(r.content)).size == (40, 40)  # the exemplar
    _finish(service, job["id"], side=200)
    after = client.get(f"/api/jobs/{job['id']}").json()["thumbnail"]
    assert after != job["thumbnail"]  # the query changes, so a cached exemplar thumbnail is not reused
    image = Image.open(io.BytesIO(client.get(after).content))
    assert image.size == (66, 66)  # 200 px in blocks of 3 (the last 2 px dropped): at most 96


def test_all_artifacts_in_one_zip(open_api):
    client, service = open_api
    job = _submit(client).json()
    assert job["artifacts_zip"] is None
    assert client.get(f"/api/jobs/{job['id']}/artifacts.zip").status_code == 404
    _finish(service, job["id"])
    public = client.get(f"/api/jobs/{job['id']}").json()
    r = client.get(public["artifacts_zip"])
    assert r.status_code == 200 and r.headers["content-type"] == "application/zip"
    assert job["id"] in r.headers["content-disposition"]
    with zipfile.ZipFile(io.BytesIO(r.content)) as archive:
        names = archive.namelist()
        assert names == [f"{job['id']}/{n}" for n in ("output.png", "metrics.json", "plots/grey.png")]
        assert (
            archive.read(names[0]) == (service.store.job_dir(job["id"]) / "out" / "output.png").read_bytes()
        )
    assert client.get("/api/jobs/nope/artifacts.zip").status_code == 404


def test_the_zip_and_thumbnail_keep_ownership_and_signed_urls(tmp_path):
    from tests.service.test_tokens import ALICE, BOB, A, B

    client, service = _client(Settings(data_dir=tmp_path / "data", api_tokens=f"alice:{ALICE}, bob:{BOB}"))
    with client:
        job = client.post(
            "/api/jobs",
            headers=A,
            data={"method": "wei-levoy", "width": "32", "height": "32"},
            files={"exemplar": ("e.png", _png(40))},
        ).json()
        _finish(service, job["id"])
        public = client.get(f"/api/jobs/{job['id']}", headers=A).json()
        for url in (public["artifacts_zip"], public["thumbnail"]):
            assert "access=" in url and client.get(url).status_code == 200  # signed: no header needed
            bare = url.split("?")[0]
            assert client.get(bare).status_code == 401
            assert client.get(bare, headers=B).status_code == 404  # another token's job


def test_delete_removes_an_own_finished_job(open_api):
    client, service = open_api
    job = _submit(client).json()
    _finish(service, job["id"])
    assert client.delete(f"/api/jobs/{job['id']}").json()["state"] == "deleted"
    assert client.get(f"/api/jobs/{job['id']}").status_code == 404
    assert client.get("/api/jobs").json()["count"] == 0


# -- volumes: voxel size -------------------------------------------------------------------------------


def test_voxel_size_is_checked_and_kept(open_api):
    client, service = open_api
    base = {"method": "solid-kopf", "width": "16", "height": "16", "depth": "16"}
    files = {"exemplar": ("e.png", _png(32))}
    job = client.post("/api/jobs", data={**base, "voxel_size": "0.055"}, files=files).json()
    assert (job["voxel_size"], job["voxel_unit"]) == (0.055, "nm")  # nm when only a size is given
    manifest = json.loads((service.store.job_dir(job["id"]) / "manifest.json").read_text())
    assert manifest["voxel_size"] == 0.055 and manifest["voxel_unit"] == "nm"
    plain = client.post("/api/jobs", data=base, files=files).json()
    assert plain["voxel_size"] is None and plain["voxel_unit"] is None  # uncalibrated
    for extra, loc in (
        ({"voxel_size": "0"}, "voxel_size"),
        ({"voxel_size": "2", "voxel_unit": "parsec"}, "voxel_unit"),
    ):
        r = client.post("/api/jobs", data={**base, **extra}, files=files)
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", loc], r.text
    r = client.post("/api/jobs", data={"method": "wei-levoy", "voxel_size": "1"}, files=files)
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "voxel_size"]
    assert client.post("/api/jobs", data={**base, "voxel_size": ""}, files=files).status_code == 202


def test_a_cancelled_job_never_reads_as_done(open_api):
    client, service = open_api
    job = _submit(client).json()
    token, _ = service.store.claim(job["id"], os.getpid(), 10.0)
    assert service.store.progress(job["id"], token, "writing artifacts", 1.0)
    client.delete(f"/api/jobs/{job['id']}")  # cancel requested while it writes
    assert service.store.finish(job["id"], token, "cancelled", "cancelled by request")
    public = client.get(f"/api/jobs/{job['id']}").json()
    assert public["state"] == "cancelled" and public["fraction"] < 1.0
    queued = _submit(client).json()
    client.delete(f"/api/jobs/{queued['id']}")
    public = client.get(f"/api/jobs/{queued['id']}").json()
    assert public["state"] == "cancelled" and public["fraction"] == 0.0
