"""The batch client (``texsynth.app.client``): retries, ``Retry-After``, typed answers, array inputs, file
names, streamed downloads, ``submit_many``/``wait_all`` through an API restart, and ``texsynth submit``.

The retry rules are shown on a tiny scripted HTTP server in a thread (each answer chosen by the test,
every request recorded); the restart on a real ``texsynth serve`` that the test stops and starts again
on the same port and data directory while ``wait_all`` polls 20 jobs.
"""

from __future__ import annotations

import email.utils
import io
import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import numpy as np
import pytest
import tifffile
from PIL import Image

from tests.service.conftest import Service, free_port
from texsynth.app.client import Client, Retry, ServiceError, encode_array, retry_after
from texsynth.app.schemas import JobPublic
from texsynth.synth.errors import InvalidInput
from texsynth.synth.io import load_image

JOB = {
    "id": "j1",
    "url": "/api/jobs/j1",
    "page": "/#/jobs/j1",
    "state": "succeeded",
    "method": "test-blur",
    "params": {},
    "size": {"width": 8, "height": 8},
    "seed": 1,
    "stage": "done",
    "fraction": 1.0,
    "message": "",
    "cancel_requested": False,
    "attempts": 1,
    "created": 0.0,
    "started": 0.0,
    "finished": 1.0,
    "elapsed": 1.0,
    "timings": {},
    "metrics": {},
    "artifacts": {"big.bin": "/api/jobs/j1/artifacts/big.bin"},
    "inputs": {},
}


class Scripted:
    """A local HTTP server that answers each request with the next of ``answers`` (status, headers,
    body; or ``"drop"``: close the connection without answering; ``"short"``: promise more bytes
    than it sends), then repeats the last; ``requests`` records (method, path, body, time)."""

    def __init__(self, answers: list) -> None:
        self.answers = list(answers)
        self.requests: list[tuple[str, str, bytes, float]] = []
        outer = self

        class Handler(BaseHTTPRequestHandler):
            def _answer(self) -> None:
                length = int(self.headers.get("Content-Length") or 0)
                body = self.rfile.read(length) if length else b""
                outer.requests.append((self.command, self.path, body, time.monotonic()))
                answer = outer.answers.pop(0) if len(outer.answers) > 1 else outer.answers[0]
                if answer == "drop":
                    self.close_connection = True
                    self.connection.shutdown(2)
                    return
                if answer == "short":
                    self.send_response(200)
                    self.send_header("Content-Length", "1000000")
                    self.end_headers()
                    self.wfile.write(b"x" * 1000)
                    self.close_connection = True
                    return
                status, headers, payload = answer
                data = payload if isinstance(payload, bytes) else json.dumps(payload).encode()
                self.send_response(status)
                for name, value in headers.items():
                    self.send_header(name, value)
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            do_GET = do_POST = do_DELETE = _answer  # noqa: N815  (http.server's names)

            def log_message(self, *args: object) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def scripted():
    servers: list[Scripted] = []

    def make(answers: list) -> Scripted:
        servers.append(Scripted(answers))
        return servers[-1]

    yield make
    for server in servers:
        server.close()


def _client(url: str, waits: list, *, fake_sleep: bool = True, **retry) -> Client:
    client = Client(
        url,
        timeout=5,
        retry=Retry(**{"seed": 3, **retry}),
        on_retry=lambda w, e, s: waits.append((e.status, s)),
    )
    if fake_sleep:
        client._sleep = lambda seconds: None
    return client


def test_a_429_with_retry_after_in_seconds_is_honoured_then_the_job_is_typed(scripted):
    server = scripted(
        [(429, {"Retry-After": "1"}, {"detail": "too many jobs queued", "field": None}), (202, {}, JOB)]
    )
    waits: list = []
    job = _client(server.url, waits, fake_sleep=False).submit(
        b"\x89PNG\r\n\x1a\n", method="test-blur", width=8
    )
    assert (
        isinstance(job, JobPublic) and job.state == "succeeded" and job["id"] == "j1"
    )  # typed, and as before
    assert len(server.requests) == 2 and [s for s, _ in waits] == [429]
    assert waits[0][1] >= 1.0  # at least what the service asked
    assert server.requests[1][3] - server.requests[0][3] >= 1.0  # the client slept it (a lower bound only)


def test_a_retry_after_http_date_is_honoured_and_one_beyond_the_budget_fails_at_once(scripted):
    later = email.utils.formatdate(time.time() + 20, usegmt=True)
    assert 18 <= retry_after(later) <= 20 and retry_after("7") == 7 and retry_after("soon") is None
    server = scripted([(503, {"Retry-After": later}, {"detail": "restarting"}), (200, {}, JOB)])
    waits: list = []
    assert _client(server.url, waits).job("j1").id == "j1"
    assert waits[0][0] == 503 and 18 <= waits[0][1] <= 20
    hour = scripted([(429, {"Retry-After": "3600"}, {"detail": "too many jobs queued"})])
    waits = []
    with pytest.raises(ServiceError) as info:
        _client(hour.url, waits, total=60).job("j1")
    assert info.value.status == 429 and "retry after 3600 s" in str(info.value)
    assert waits == [] and len(hour.requests) == 1  # no wait that the budget cannot hold


def test_backoff_is_exponential_with_seeded_jitter_and_bounded(scripted):
    server = scripted([(502, {}, b"bad gateway")] * 6 + [(200, {}, JOB)])
    waits_a: list = []
    waits_b: list = []
    assert _client(server.url, waits_a, base=0.5, cap=4).job("j1").state == "succeeded"
    server.answers = [(502, {}, b"bad gateway")] * 6 + [(200, {}, JOB)]
    _client(server.url, waits_b, base=0.5, cap=4).job("j1")
    assert waits_a == waits_b  # the same seed, the same waits
    assert [s for s, _ in waits_a] == [502] * 6
    bounds = [min(4, 0.5 * 2**n) for n in range(6)]
    assert all(0 <= w <= b for (_, w), b in zip(waits_a, bounds, strict=True))
    assert sum(w for _, w in waits_a) > 0  # jitter is not all zero
    other: list = []
    server.answers = [(502, {}, b"bad gateway")] * 6 + [(200, {}, JOB)]
    _client(server.url, other, base=0.5, cap=4, seed=4).job("j1")
    assert other != waits_a
    # bounded: a service that never recovers ends in the last error after `attempts` tries
    dead = scripted([(500, {}, {"detail": "internal error"})])
    with pytest.raises(ServiceError) as info:
        _client(dead.url, [], attempts=4).job("j1")
    assert info.value.status == 500 and len(dead.requests) == 4


def test_what_may_have_acted_is_not_resent(scripted):
    server = scripted([(500, {}, {"detail": "internal error"}), (202, {}, JOB)])
    with pytest.raises(ServiceError) as info:
        _client(server.url, []).submit(b"\x89PNG\r\n\x1a\n", method="test-blur")
    assert info.value.status == 500 and len(server.requests) == 1  # a POST after a 500: maybe queued
    gone = scripted([(422, {}, {"detail": "levels: too many", "field": "levels"})])
    with pytest.raises(ServiceError) as info:
        _client(gone.url, []).job("j1")
    assert (info.value.status, info.value.field, len(gone.requests)) == (422, "levels", 1)
    refused = Client(f"http://127.0.0.1:{free_port()}", retry=Retry(attempts=3, seed=0))
    refused._sleep = lambda seconds: None
    with pytest.raises(ServiceError) as info:
        refused.job("j1")
    assert info.value.status == 0 and "cannot reach" in info.value.detail


def test_wait_outlasts_failed_polls_and_ends_on_404(scripted):
    running = {**JOB, "state": "running", "fraction": 0.5}
    server = scripted(
        [(200, {}, running), "drop", (500, {}, {"detail": "oops"}), (503, {}, b""), (200, {}, JOB)]
    )
    seen: list = []
    client = _client(server.url, [], attempts=1)  # every failure reaches wait() itself
    final = client.wait("j1", progress=lambda j: seen.append(j.state), poll=0)
    assert final.state == "succeeded" and seen == ["running", "succeeded"] and len(server.requests) == 5
    missing = scripted([(404, {}, {"detail": "no job with id 'j1'"})])
    with pytest.raises(ServiceError) as info:
        _client(missing.url, []).wait("j1", poll=0)
    assert info.value.status == 404


def test_downloads_stream_to_files_and_a_broken_stream_is_fetched_again(scripted, tmp_path):
    payload = np.random.default_rng(0).bytes(3 * 2**20)
    server = scripted(["short", (200, {"Content-Type": "application/octet-stream"}, payload)])
    waits: list = []
    paths = _client(server.url, waits).download(JOB, tmp_path / "out")
    assert paths == [tmp_path / "out" / "big.bin"] and paths[0].read_bytes() == payload
    assert [s for s, _ in waits] == [0] and sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "big.bin"
    ]


def _filenames(body: bytes) -> dict[str, str]:
    out = {}
    for part in body.split(b"Content-Disposition: form-data; ")[1:]:
        head = part.split(b"\r\n", 1)[0].decode()
        fields = dict(item.split("=", 1) for item in head.split("; "))
        if "filename" in fields:
            out[fields["name"].strip('"')] = fields["filename"].strip('"')
        else:
            out[fields["name"].strip('"')] = part.split(b"\r\n\r\n", 1)[1].split(b"\r\n", 1)[0].decode()
    return out


def test_inputs_keep_their_names_and_sizes_are_keywords(scripted, tmp_path):
    server = scripted([(202, {}, JOB)])
    client = _client(server.url, [])
    path = tmp_path / "carbon soot.tif"
    tifffile.imwrite(path, np.zeros((8, 8), np.uint16))
    client.submit(path, method="test-blur", width=96, height=64, constraint=("rings.png", b"\x89PNG..."))
    client.submit(path.read_bytes(), method="test-blur", exemplars={"xy": np.zeros((4, 4), np.uint8)})
    first, second = (_filenames(r[2]) for r in server.requests)
    assert first["exemplar"] == "carbon soot.tif" and first["constraint"] == "rings.png"
    assert (first["width"], first["height"], "depth" not in first) == ("96", "64", True)
    assert second["exemplar"] == "exemplar.tiff" and second["exemplar_xy"] == "exemplar_xy.png"
    with pytest.raises(InvalidInput, match="given twice"):
        client.submit(path, width=96, size={"width": 64})


def test_arrays_are_encoded_losslessly_in_their_dtypes_range():
    rng = np.random.default_rng(1)
    grey8 = rng.integers(0, 256, (12, 20), dtype=np.uint8)
    name, data = encode_array(grey8)
    with Image.open(io.BytesIO(data)) as im:
        assert (name, im.format, im.mode) == ("exemplar.png", "PNG", "L")
        assert np.array_equal(np.asarray(im), grey8)
    grey16 = rng.integers(0, 65536, (12, 20), dtype=np.uint16)
    name, data = encode_array(grey16, "constraint")
    with Image.open(io.BytesIO(data)) as im:
        assert name == "constraint.png" and im.mode.startswith("I")
        assert np.array_equal(np.asarray(im).astype(np.uint16), grey16)
    rgb16 = rng.integers(0, 65536, (12, 20, 3), dtype=np.uint16)
    name, data = encode_array(rgb16)
    assert name == "exemplar.tiff" and np.array_equal(tifffile.imread(io.BytesIO(data)), rgb16)
    unit = rng.random((12, 20), dtype=np.float32)
    _, data = encode_array(unit)
    assert np.abs(load_image(data) - unit).max() <= 0.5 / 65535 + 1e-7  # 16 bits, not 8
    _, data = encode_array(unit > 0.5)
    assert set(np.unique(load_image(data))) <= {0.0, 1.0}
    with pytest.raises(InvalidInput, match=r"outside \[0, 1\]: scale it first") as info:
        encode_array(unit * 255)
    assert info.value.source == "exemplar"
    with pytest.raises(InvalidInput, match="int32"):
        encode_array(grey8.astype(np.int32))


# -- against real service processes ------------------------------------------------------------------

TINY = {"steps": 1, "delay": 0.2}


@pytest.mark.integration
@pytest.mark.slow
def test_wait_all_of_20_jobs_outlasts_an_api_restart_and_a_full_queue(tmp_path, exemplar_png):
    """20 tiny jobs through a queue limit of 8 (the service's own 429s) and an API restart."""
    service = Service(tmp_path / "data", {"TEXSYNTH_MAX_QUEUED_PER_TOKEN": "8"}, concurrency=1)
    retries: list = []
    client = Client(
        service.url,
        timeout=10,
        retry=Retry(base=0.2, cap=1.0, seed=1),
        on_retry=lambda what, error, wait: retries.append((what, error.status)),
    )
    restarted = threading.Event()
    unfinished_at_restart: list[int] = []
    restarts: list[threading.Thread] = []

    def restart_once(job, finished: int, total: int) -> None:
        if not restarted.is_set():
            restarted.set()
            unfinished_at_restart.append(total - finished)
            service.stop()
            restarts.append(threading.Thread(target=service.start, daemon=True))
            restarts[0].start()

    try:
        service.start()
        exemplar = np.asarray(Image.open(io.BytesIO(exemplar_png)))[:16, :16]  # a uint8 array
        jobs = client.submit_many(
            [{"seed": seed} for seed in range(20)],
            exemplar=exemplar,
            method="test-blur",
            params=TINY,
            width=24,
            height=16,
        )
        assert len({j.id for j in jobs}) == 20
        assert any(status == 429 for _, status in retries), "the queue limit was never reached"
        final = client.wait_all(jobs, progress=restart_once, poll=0.2, timeout=240)
        assert [j.id for j in final] == [j.id for j in jobs]
        assert {j.state for j in final} == {"succeeded"}, [j.message for j in final if j.state != "succeeded"]
        assert unfinished_at_restart[0] > 0
        assert any(status == 0 for _, status in retries), "no poll met the API down"
        assert {j.size["width"] for j in final} == {24} and {j.size["height"] for j in final} == {16}
        with Image.open(io.BytesIO(client.artifact(final[0], "output.png"))) as im:
            assert im.size == (24, 16)  # width x height, as asked by keyword
    finally:
        for thread in restarts:  # its readiness poll must end before the stop (or it fails the next test)
            thread.join(timeout=90)
        service.stop()
        client.close()


@pytest.mark.integration
def test_texsynth_submit_uses_the_client_with_width_and_height(embedded, exemplar_png, tmp_path, capsys):
    from texsynth.synth.cli import main

    exemplar = tmp_path / "fringes.png"
    exemplar.write_bytes(exemplar_png)
    args = ["submit", str(exemplar), "--url", embedded.url, "--method", "test-blur"]
    args += [
        "--width",
        "40",
        "--height",
        "24",
        "--set",
        "steps=1",
        "--set",
        "delay=0",
        "--out",
        str(tmp_path),
    ]
    assert main(args) == 0
    folder = capsys.readouterr().out.strip().splitlines()[-1]
    with Image.open(f"{folder}/output.png") as im:
        assert im.size == (40, 24)
    names = {p.name for p in (tmp_path / folder.rsplit("/", 1)[-1]).iterdir()}
    assert {"output.png", "metrics.json", "manifest.json"} <= names and not any(
        n.endswith(".part") for n in names
    )
