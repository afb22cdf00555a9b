from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from tests.service.svc_helpers import FakeStream


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return Settings(
        db_url=f"sqlite:///{tmp_path / 'fd.db'}",
        executor="serial",
        events_poll_seconds=0.02,
        sweep_chunk=16,
        status_cache_seconds=0,
    )


@pytest.fixture
def fake() -> FakeStream:
    return FakeStream()


@pytest.fixture
def client(settings: Settings, fake: FakeStream) -> Iterator[TestClient]:
    with TestClient(create_app(settings, stream=fake)) as c:
        yield c
