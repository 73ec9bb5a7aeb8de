"""A hostile probe of the running service (issue 26): odd multipart, huge and malformed heads, unicode
and path-like file names, negative and enormous sizes, odd JSON. Every answer is a 4xx (or a clean
success where the input is valid after all), never a 5xx; nothing is stored for a refused request; the
jobs submitted before the probe all succeed and the service still takes a normal job afterwards.
"""

from __future__ import annotations

import json
import socket

import httpx
import pytest

from tests.service.conftest import Service

pytestmark = pytest.mark.integration

JOB = {"method": "test-blur", "params": '{"steps": 1}', "width": "32", "height": "32"}


def _raw(service: Service, request: bytes) -> bytes:
    """Send raw bytes; the server's first answer (head and body), or what came before it closed."""
    with socket.create_connection(("127.0.0.1", service.port), timeout=5) as sock:
        answer = b""
        try:
            sock.sendall(request)
            while b"\r\n\r\n" not in answer and (chunk := sock.recv(65536)):
                answer += chunk
            head = answer.partition(b"\r\n\r\n")[0].lower()
            length = int(head.partition(b"content-length:")[2].split(b"\r\n")[0] or 0)
            while len(answer.partition(b"\r\n\r\n")[2]) < length and (chunk := sock.recv(65536)):
                answer += chunk
        except OSError:  # reset by the server, or nothing within 5 s
            pass
    return answer


def _status(answer: bytes) -> int | None:
    first = answer.split(b"\r\n", 1)[0].split()
    return int(first[1]) if len(first) >= 2 and first[1].isdigit() else None


def _multipart(boundary: bytes, parts: list[bytes], end: bool = True) -> bytes:
    body = b"".join(b"--" + boundary + b"\r\n" + part + b"\r\n" for part in parts)
    return body + (b"--" + boundary + b"--\r\n" if end else b"")


def _field(name: bytes, value: bytes, filename: bytes | None = None) -> bytes:
    disposition = b'Content-Disposition: form-data; name="' + name + b'"'
    if filename is not None:
        disposition += b'; filename="' + filename + b'"\r\nContent-Type: image/png'
    return disposition + b"\r\n\r\n" + value


def _post(body: bytes, content_type: bytes, extra: bytes = b"") -> bytes:
    return (
        b"POST /api/jobs HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\nContent-Type: "
        + content_type
        + b"\r\nContent-Length: "
        + str(len(body)).encode()
        + b"\r\n"
        + extra
        + b"\r\n"
        + body
    )


H = b" HTTP/1.1\r\nHost: localhost\r\n"


def _raw_cases(png: bytes) -> dict[str, bytes]:
    b = b"xyz"
    job = [_field(b"method", b"test-blur"), _field(b"width", b"32"), _field(b"height", b"32")]
    return {
        "huge header": b"GET /api/jobs HTTP/1.1\r\nHost: localhost\r\nX-Big: " + b"a" * 40000 + b"\r\n\r\n",
        "many headers": b"GET /api/jobs HTTP/1.1\r\nHost: localhost\r\n" + b"X-A: b\r\n" * 5000 + b"\r\n",
        "negative content-length": b"POST /api/jobs" + H + b"Content-Length: -1\r\n\r\n",
        "two content-lengths": b"POST /api/jobs HTTP/1.1\r\nHost: localhost\r\nContent-Length: 5\r\n"
        b"Content-Length: 7\r\n\r\nabcde",
        "bad chunk": b"POST /api/jobs" + H + b"Transfer-Encoding: chunked\r\n\r\nzz\r\n",
        "request line garbage": b"\x00\x01\x02 / HTTP/1.1\r\n\r\n",
        "http/0.9": b"GET /\r\n\r\n",
        "no boundary": _post(_multipart(b, [*job]), b"multipart/form-data"),
        "wrong boundary": _post(_multipart(b, [*job]), b"multipart/form-data; boundary=other"),
        "unterminated multipart": _post(
            _multipart(b, [*job], end=False), b"multipart/form-data; boundary=xyz"
        ),
        "part without name": _post(
            _multipart(b, [*job, b"Content-Disposition: form-data\r\n\r\nvalue"]),
            b"multipart/form-data; boundary=xyz",
        ),
        "part without headers": _post(
            _multipart(b, [*job, b"\r\nbare"]), b"multipart/form-data; boundary=xyz"
        ),
        "exemplar as a text field": _post(
            _multipart(b, [*job, _field(b"exemplar", png)]), b"multipart/form-data; boundary=xyz"
        ),
        "two exemplars": _post(
            _multipart(b, [*job, _field(b"exemplar", png, b"a.png"), _field(b"exemplar", png, b"b.png")]),
            b"multipart/form-data; boundary=xyz",
        ),
        "file name with a NUL and CRLF": _post(
            _multipart(b, [*job, _field(b"exemplar", png, b"a\x00b\r\nX-Injected: 1.png")]),
            b"multipart/form-data; boundary=xyz",
        ),
        "latin-1 file name": _post(
            _multipart(b, [*job, _field(b"exemplar", png, "é\xff.png".encode("latin-1"))]),
            b"multipart/form-data; boundary=xyz",
        ),
        "content-length larger than the body": _post(
            _multipart(b, [*job]), b"multipart/form-data; boundary=xyz"
        )[:-20],
        "urlencoded instead of multipart": _post(
            b"method=test-blur&width=-3&height=32", b"application/x-www-form-urlencoded"
        ),
        "json instead of multipart": _post(json.dumps({"method": "test-blur"}).encode(), b"application/json"),
        "a million parts": _post(
            _multipart(b, [_field(b"x", b"1")] * 20000), b"multipart/form-data; boundary=xyz"
        ),
        "host with a NUL": b"GET /api/jobs HTTP/1.1\r\nHost: local\x00host\r\n\r\n",
        "path traversal": b"GET /api/jobs/..%2f..%2fjobs.sqlite HTTP/1.1\r\nHost: localhost\r\n\r\n",
        "artifact traversal": b"GET /api/jobs/x/artifacts/../../../jobs.sqlite" + H + b"\r\n",
        "percent-encoded NUL": b"GET /api/jobs/%00 HTTP/1.1\r\nHost: localhost\r\n\r\n",
        "invalid utf-8 path": b"GET /api/jobs/%ff%fe HTTP/1.1\r\nHost: localhost\r\n\r\n",
        "long query": b"GET /api/jobs?state=" + b"q" * 12000 + b" HTTP/1.1\r\nHost: localhost\r\n\r\n",
    }


def _form_cases() -> dict[str, dict[str, str]]:
    return {
        "negative width": {**JOB, "width": "-5"},
        "zero height": {**JOB, "height": "0"},
        "enormous width": {**JOB, "width": "99999999999999999999999"},
        "width as text": {**JOB, "width": "wide"},
        "width with spaces and a sign": {**JOB, "width": " +32 "},
        "float width": {**JOB, "width": "32.5"},
        "depth for a 2-D method": {**JOB, "depth": "8"},
        "negative seed": {**JOB, "seed": "-1"},
        "seed beyond 2**64": {**JOB, "seed": str(2**64)},
        "params null": {**JOB, "params": "null"},
        "params a list": {**JOB, "params": "[1, 2]"},
        "params a string": {**JOB, "params": '"steps"'},
        "params unterminated": {**JOB, "params": '{"steps": '},
        "params 5000-digit integer": {**JOB, "params": '{"steps": ' + "9" * 5000 + "}"},
        "params NaN": {**JOB, "params": '{"sigma": NaN}'},
        "params 1e400": {**JOB, "params": '{"sigma": 1e400}'},
        "params unicode key": {**JOB, "params": '{"ü\\u0000": 1}'},
        "params lone surrogate": {**JOB, "params": '{"steps": "\\ud800"}'},
        "params width negative": {**JOB, "params": '{"width": -3}'},
        "method empty": {**JOB, "method": ""},
        "method path": {**JOB, "method": "../../etc/passwd"},
        "method unicode": {**JOB, "method": "wéi-levoy\u202e"},
    }


@pytest.fixture
def png(exemplar_png) -> bytes:
    return exemplar_png


def test_hostile_requests_get_4xx_and_leave_nothing_behind(embedded, png):
    client = embedded.client()
    before = [
        client.submit(png, method="test-blur", params={"width": 32, "height": 32, "steps": 2})
        for _ in range(3)
    ]
    store = embedded.store()
    count = store.count()
    answers = {}
    for name, request in _raw_cases(png).items():
        answer = _raw(embedded, request)
        answers[name] = _status(answer)
        assert answers[name] is None or answers[name] < 500, (name, answer[:300])
    files = {"exemplar": ("e.png", png, "image/png")}
    for name, data in _form_cases().items():
        r = httpx.post(embedded.url + "/api/jobs", data=data, files=files, timeout=30)
        answers[name] = r.status_code
        assert r.status_code < 500, (name, r.text)
        if r.status_code >= 400:
            assert r.json()["detail"], name  # a message a person can act on
    for name, path in {
        "limit -1": "/api/jobs?limit=-1",
        "offset 10**30": "/api/jobs?offset=" + "9" * 30,
        "negative slice": f"/api/jobs/{before[0]['id']}/slices/xy/-1.png",
        "slice of a 2-D job": f"/api/jobs/{before[0]['id']}/slices/xy/0.png",
        "unknown plane": f"/api/jobs/{before[0]['id']}/slices/ab/0.png",
        "sweep csv of nothing": "/api/sweeps/none?format=csv",
    }.items():
        r = httpx.get(embedded.url + path, timeout=30)
        answers[name] = r.status_code
        assert 400 <= r.status_code < 500, (name, r.status_code, r.text)
    for name, filename in {
        "unicode file name": "ексемплар 🌀.png",
        "path-like file name": "../../../../etc/passwd.png",
        "very long file name": "a" * 5000 + ".png",  # the multipart parser may refuse it (400)
    }.items():
        r = httpx.post(
            embedded.url + "/api/jobs", data=JOB, files={"exemplar": (filename, png, "image/png")}, timeout=30
        )
        answers[name] = r.status_code
        assert r.status_code == 202 or (name == "very long file name" and r.status_code == 400), (
            name,
            r.text,
        )
        if r.status_code == 202:  # a valid job: the client's file name is never a stored path
            inputs = r.json()["inputs"]  # role -> URL of the stored file, named by the role
            assert list(inputs) == ["exemplar"] and filename not in json.dumps(inputs)
    print(json.dumps(answers, indent=1))  # the probe's answers, for the record (pytest -s)
    accepted = [name for name, status in answers.items() if status == 202]
    # the valid jobs above (file names, and the forms that are valid after all), and nothing else
    assert store.count() == count + len(accepted), accepted
    r = httpx.get(embedded.url + "/api/health", timeout=10)
    assert r.status_code == 200, r.text
    for job in before:
        assert client.wait(job["id"], timeout=120)["state"] == "succeeded"
    after = client.submit(png, method="test-blur", params={"width": 32, "height": 32, "steps": 2})
    assert client.wait(after["id"], timeout=120)["state"] == "succeeded"
