"""The worker container's health check (``python -m texsynth.worker.health``, docker-compose's worker
test)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.service.conftest import REPO

pytestmark = pytest.mark.integration


def _check(data_dir) -> subprocess.CompletedProcess:
    env = {**os.environ, "TEXSYNTH_DATA_DIR": str(data_dir), "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, "-m", "texsynth.worker.health"], env=env, capture_output=True, text=True, timeout=60
    )


def test_healthy_with_a_live_worker(embedded):
    done = _check(embedded.data_dir)
    assert done.returncode == 0, done.stderr


def test_unhealthy_without_one(tmp_path):
    done = _check(tmp_path / "data")
    assert done.returncode == 1 and "no worker" in done.stderr and "reported within 30 s" in done.stderr
