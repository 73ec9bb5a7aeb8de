"""The OpenAPI document carries what client generators need (issue 29), in process: binary uploads, real
media types of files, the bearer scheme, enums of states and methods, every method's parameters."""

from __future__ import annotations

import json

from tests.service.test_tokens import ALICE, _client
from texsynth.app.openapi import params_schema_name
from texsynth.jobs.config import Settings
from texsynth.jobs.store import STATES
from texsynth.synth.api import available_methods


def _schema(settings: Settings) -> dict:
    client, _ = _client(settings)
    with client:
        return client.get("/openapi.json").json()


def test_uploads_are_binary_and_files_have_their_media_types(tmp_path):
    schema = _schema(Settings(data_dir=tmp_path / "d"))
    assert "contentMediaType" not in json.dumps(
        {k: v for k, v in schema["components"]["schemas"].items() if k.startswith("Body_")}
    ).replace('"contentMediaType": "application/json"', "")
    form = schema["components"]["schemas"]["Body_submit_job_api_jobs_post"]["properties"]
    for role in ("exemplar", "constraint", "exemplar_xy", "exemplar_xz", "exemplar_yz"):
        assert {"type": "string", "format": "binary"} in form[role]["anyOf"], role
    artifact = schema["paths"]["/api/jobs/{job_id}/artifacts/{name}"]["get"]["responses"]["200"]["content"]
    assert list(artifact) == ["image/png", "image/tiff", "application/json"]
    assert artifact["image/png"]["schema"] == {"type": "string", "format": "binary"}
    preview = schema["paths"]["/api/jobs/{job_id}/preview.png"]["get"]["responses"]["200"]["content"]
    assert list(preview) == ["image/png"]


def test_states_and_methods_are_enums_and_each_method_has_its_parameters(tmp_path):
    schema = _schema(Settings(data_dir=tmp_path / "d"))
    components = schema["components"]["schemas"]
    assert components["JobState"]["enum"] == list(STATES)
    assert components["JobPublic"]["properties"]["state"]["$ref"] == "#/components/schemas/JobState"
    methods = sorted(available_methods())
    assert components["MethodName"]["enum"] == methods
    form = components["Body_submit_job_api_jobs_post"]["properties"]
    assert form["method"]["$ref"] == "#/components/schemas/MethodName"
    members = {m["$ref"].rsplit("/", 1)[1] for m in form["params"]["contentSchema"]["oneOf"]}
    assert members == {params_schema_name(m) for m in methods}
    assert params_schema_name("wei-levoy") == "WeiLevoyParams"
    levels = components["WeiLevoyParams"]["properties"]["levels"]
    assert levels == available_methods()["wei-levoy"].schema()["properties"]["levels"]
    request = components["JobRequest"]
    assert request["discriminator"]["propertyName"] == "method"
    assert set(request["discriminator"]["mapping"]) == set(methods)
    refs = [r for r in json.dumps(components).split('"$ref": "')[1:]]
    for ref in refs:  # every reference resolves (the models' $defs were hoisted)
        assert ref.split('"', 1)[0].rsplit("/", 1)[1] in components
    state = schema["paths"]["/api/jobs"]["get"]["parameters"]
    assert {"$ref": "#/components/schemas/JobState"} in next(p for p in state if p["name"] == "state")[
        "schema"
    ]["anyOf"]


def test_the_bearer_scheme_is_declared_optional_without_tokens_and_required_with(tmp_path):
    open_schema = _schema(Settings(data_dir=tmp_path / "a"))
    assert open_schema["components"]["securitySchemes"]["bearer"]["scheme"] == "bearer"
    assert open_schema["paths"]["/api/jobs"]["post"]["security"] == [{}, {"bearer": []}]
    closed = _schema(Settings(data_dir=tmp_path / "b", api_tokens=f"alice:{ALICE}"))
    assert closed["paths"]["/api/jobs/{job_id}"]["get"]["security"] == [{"bearer": []}]
    assert "401" in closed["paths"]["/api/jobs/{job_id}"]["get"]["responses"]
    assert "security" not in closed["paths"]["/api/health"]["get"]
