"""What the browser page reads from the API (issue 27), in process: parameter schemas made for a short
form, one-line 422s per field, the favicon, examples, job lists with thumbnails, the artifacts' zip."""

from __future__ import annotations

import io
import json
import re

import numpy as np
import pytest
from PIL import Image

from jobs.config import Settings
from synth.api import available_methods
from synth.params import BOUNDS
from tests.service.test_tokens import _client

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
