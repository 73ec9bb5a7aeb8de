"""A submission the broker refuses leaves nothing behind (issue 14, item 7): no record, no folder, a 503."""

from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from texsynth.app.service import BrokerUnavailable, Service, Upload
from texsynth.jobs.config import Settings


def _png() -> bytes:
    buf = io.BytesIO()
    Image.fromarray((np.random.default_rng(0).random((32, 32)) * 255).astype(np.uint8)).save(buf, "PNG")
    return buf.getvalue()


@pytest.fixture
def service(tmp_path, monkeypatch) -> Service:
    svc = Service(Settings(data_dir=tmp_path / "data"))

    def refuse(*_args, **_kwargs):
        raise ConnectionError("connection refused")

    monkeypatch.setattr(svc, "send", refuse)
    monkeypatch.setattr(svc, "send_group", refuse)
    return svc


def test_a_refused_job_leaves_no_record_and_no_folder(service):
    request = service.validate("wei-levoy", "{}", 1, [Upload("exemplar", "e.png", _png())])
    with pytest.raises(BrokerUnavailable, match="connection refused"):
        service.submit(request)
    assert service.store.count() == 0
    assert list(service.settings.jobs_dir.iterdir()) == []


def test_a_refused_sweep_leaves_no_jobs_and_no_sweep(service):
    request = service.validate("wei-levoy", "{}", 1, [Upload("exemplar", "e.png", _png())])
    with pytest.raises(BrokerUnavailable):
        service.submit_sweep(request, {"levels": [1, 2]})
    assert service.store.count() == 0
    assert list(service.settings.jobs_dir.iterdir()) == []
    with service.store._connect() as db:
        assert db.execute("SELECT COUNT(*) FROM sweeps").fetchone()[0] == 0
