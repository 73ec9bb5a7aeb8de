"""Rejected requests: the right status, a message naming the problem, and nothing stored or queued."""

from __future__ import annotations

import json
import struct
import zlib

import httpx
import pytest

from tests.service.conftest import MAX_BODY, Service

pytestmark = pytest.mark.integration


def _png_declaring(width: int, height: int) -> bytes:
    """A tiny PNG whose header declares ``width x height`` pixels (a decompression bomb's header)."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 1, 0, 0, 0, 0)
    idat = zlib.compress(b"\x00" * 1024)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


def _queue_files(service: Service) -> list[str]:
    queue = service.data_dir / "broker" / "queue"
    return sorted(p.name for p in queue.iterdir()) if queue.exists() else []


@pytest.fixture
def nothing_queued(embedded):
    """Asserts after the test that no job record, job folder or broker message was added."""
    store = embedded.store()
    count, folders = store.count(), set((embedded.data_dir / "jobs").iterdir())
    yield
    assert store.count() == count
    assert set((embedded.data_dir / "jobs").iterdir()) == folders
    assert _queue_files(embedded) == []


def _post(service: Service, exemplar: bytes | None = None, **fields) -> httpx.Response:
    files = {"exemplar": ("exemplar.png", exemplar, "image/png")} if exemplar is not None else None
    data = {k: (json.dumps(v) if isinstance(v, dict) else str(v)) for k, v in fields.items()}
    return httpx.post(embedded_url(service) + "/api/jobs", files=files, data=data, timeout=30)


def embedded_url(service: Service) -> str:
    return service.url


@pytest.mark.usefixtures("nothing_queued")
class TestRejected:
    def test_oversize_body_413(self, embedded):
        r = _post(embedded, b"\x89PNG" + b"\0" * (MAX_BODY + 1024), method="test-blur")
        assert r.status_code == 413
        assert r.json()["error"] == "input_too_large" and "MiB" in r.json()["detail"]

    def test_decompression_bomb_413(self, embedded):
        r = _post(embedded, _png_declaring(60000, 60000), method="test-blur")
        assert r.status_code == 413, r.text
        assert r.json()["field"] == "exemplar" and "pixels" in r.json()["detail"]

    def test_not_an_image_415(self, embedded):
        r = _post(embedded, b"%PDF-1.4 this is not an image", method="test-blur")
        assert r.status_code == 415 and r.json()["field"] == "exemplar"

    def test_truncated_image_422(self, embedded, exemplar_png):
        r = _post(embedded, exemplar_png[: len(exemplar_png) // 2], method="test-blur")
        assert r.status_code == 422 and r.json()["field"] == "exemplar"
        assert "truncated" in r.json()["message"] or "corrupt" in r.json()["message"]

    @pytest.mark.parametrize(
        ("params", "field"),
        [
            ({"steps": 0}, "steps"),
            ({"sigma": "wide"}, "sigma"),
            ({"no_such_parameter": 1}, "no_such_parameter"),
            ({"width": 100000, "height": 64}, "width"),
            ({"width": 64, "height": 2.5}, "height"),
        ],
    )
    def test_bad_parameter_422_names_the_field(self, embedded, exemplar_png, params, field):
        r = _post(embedded, exemplar_png, method="test-blur", params=params)
        assert r.status_code == 422, r.text
        assert r.json()["field"] == field and field in r.json()["message"]

    @pytest.mark.parametrize(
        ("method", "params", "field", "words"),
        [
            ("quilting", {"patch_size": 100}, "patch_size", "larger than the exemplar (64 x 64)"),
            ("gaussian-patch", {"patch_size": 60, "neighbours": 100}, "neighbours", "larger than the number"),
            ("wei-levoy", {"levels": 6}, "neighbourhood_size", "no neighbourhood fits inside the exemplar"),
            ("tensor-constrained", {"structure_levels": 6}, "neighbourhood_size", "at pyramid level"),
        ],
    )
    def test_geometry_against_the_exemplar_422_before_queueing(
        self, embedded, exemplar_png, method, params, field, words
    ):
        """What the method would only find out in the worker (the patch or the neighbourhood does not fit
        the 64x64 exemplar) is checked at submission from the exemplar's shape."""
        r = _post(embedded, exemplar_png, method=method, params={"width": 64, "height": 64, **params})
        assert r.status_code == 422, r.text
        assert r.json()["field"] == field and words in r.json()["message"]

    @pytest.mark.parametrize("method", ["solid-kopf", "solid-chen-wang"])
    def test_a_structured_start_on_a_tiny_exemplar_422_before_queueing(self, embedded, method):
        """An 11x11 exemplar holds no fringe period to measure: structure='laminar' is refused at submission,
        naming the exemplar (it crashed in the worker before)."""
        import io

        import numpy as np
        from PIL import Image

        buffer = io.BytesIO()
        pixels = (np.random.default_rng(0).random((11, 11)) * 255).astype(np.uint8)
        Image.fromarray(pixels).save(buffer, format="PNG")
        params = {"width": 16, "height": 16, "depth": 16, "structure": "laminar"}
        r = _post(embedded, buffer.getvalue(), method=method, params=params)
        assert r.status_code == 422, r.text
        assert (
            r.json()["field"] == "exemplar"
            and "too small to measure its fringe period" in r.json()["message"]
        )

    @pytest.mark.parametrize(
        ("params", "fields", "field", "words"),
        [
            ({"width": 64}, {"width": 48}, "width", "given twice"),
            ({}, {"width": 100000}, "width", "each side must lie in"),
            ({}, {"height": "tall"}, "height", ""),
        ],
    )
    def test_size_form_fields_are_checked_422(self, embedded, exemplar_png, params, fields, field, words):
        r = _post(embedded, exemplar_png, method="test-blur", params=params, **fields)
        assert r.status_code == 422, r.text
        assert r.json()["field"] == field and words in r.json()["message"]

    def test_params_not_json_422(self, embedded, exemplar_png):
        r = _post(embedded, exemplar_png, method="test-blur", params="{width: 3")
        assert r.status_code == 422 and r.json()["field"] == "params"

    def test_unknown_method_422(self, embedded, exemplar_png):
        r = _post(embedded, exemplar_png, method="no-such-method")
        assert r.status_code == 422 and r.json()["field"] == "method" and "test-blur" in r.json()["message"]

    def test_missing_exemplar_422(self, embedded):
        r = _post(embedded, None, method="test-blur")
        assert r.status_code == 422 and r.json()["field"] == "exemplar"

    def test_unknown_job_404(self, embedded):
        for method, path in (
            ("GET", "/api/jobs/nope"),
            ("DELETE", "/api/jobs/nope"),
            ("GET", "/api/jobs/nope/artifacts/output.png"),
            ("GET", "/api/sweeps/nope"),
        ):
            r = httpx.request(method, embedded.url + path)
            assert r.status_code == 404 and "nope" in r.json()["detail"]

    def test_bad_sweep_grid_422(self, embedded, exemplar_png):
        r = httpx.post(
            embedded.url + "/api/sweeps",
            files={"exemplar": ("e.png", exemplar_png, "image/png")},
            data={"method": "test-blur", "grid": json.dumps({"steps": [1, 0]})},
        )
        assert r.status_code == 422 and r.json()["field"] == "grid.steps"

    def test_sweep_geometry_422_names_the_grid_field(self, embedded, exemplar_png):
        r = httpx.post(
            embedded.url + "/api/sweeps",
            files={"exemplar": ("e.png", exemplar_png, "image/png")},
            data={"method": "quilting", "grid": json.dumps({"patch_size": [16, 100]})},
        )
        assert r.status_code == 422 and r.json()["field"] == "grid.patch_size", r.text


@pytest.mark.usefixtures("nothing_queued")
class TestNonFiniteAndHuge:
    """Requests that gave 500s (issue 14, item 4) answer 4xx and name the field."""

    @pytest.mark.parametrize(
        ("raw", "field", "detail"),
        [
            ('{"sigma": NaN}', "params", "NaN is not a number JSON allows"),
            ('{"sigma": Infinity}', "params", "Infinity is not a number JSON allows"),
            ('{"sigma": 1e400}', "sigma", "must be a finite number"),
        ],
    )
    def test_non_finite_params_422(self, embedded, exemplar_png, raw, field, detail):
        r = _post(embedded, exemplar_png, method="test-blur", params=raw)
        assert r.status_code == 422, r.text
        assert r.json()["field"] == field and detail in r.json()["message"]

    def test_non_finite_sweep_grid_422(self, embedded, exemplar_png):
        r = httpx.post(
            embedded.url + "/api/sweeps",
            files={"exemplar": ("e.png", exemplar_png, "image/png")},
            data={"method": "test-blur", "grid": '{"sigma": [1.0, NaN]}'},
        )
        assert r.status_code == 422 and r.json()["field"] == "grid"

    def test_huge_offset_422(self, embedded):
        r = httpx.get(embedded.url + "/api/jobs", params={"offset": 2**63})
        assert r.status_code == 422 and r.json()["field"] == "offset"

    def test_unknown_state_filter_422_names_the_field(self, embedded):
        r = httpx.get(embedded.url + "/api/jobs", params={"state": "bogus"})
        body = r.json()
        assert r.status_code == 422 and body["field"] == "state"
        assert "succeeded" in body["message"] and "'bogus'" in body["message"]


@pytest.mark.usefixtures("nothing_queued")
def test_an_empty_method_is_refused_not_replaced(embedded, exemplar_png):
    r = _post(embedded, exemplar_png, method="")
    assert r.status_code == 422 and r.json()["field"] == "method"


def test_submit_prints_the_service_message_not_json_and_names_a_missing_file(embedded, tmp_path, capsys):
    from texsynth.synth.cli import main

    assert main(["submit", str(tmp_path / "missing.png"), "--url", embedded.url]) == 2
    err = capsys.readouterr().err
    assert "exemplar: cannot read" in err and "missing.png" in err and "Traceback" not in err
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image at all")
    assert main(["submit", str(bad), "--url", embedded.url, "--method", "test-blur"]) == 2
    err = capsys.readouterr().err
    assert "HTTP 415: exemplar:" in err and "{" not in err
