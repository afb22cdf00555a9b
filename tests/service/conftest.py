from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from finaldrive.service.config import Settings
from finaldrive.service.main import create_app
from tests.service.svc_helpers import ToyTask, running_scheduler


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return Settings(db_url=f"sqlite:///{tmp_path / 'fd.db'}", executor="serial", events_poll_seconds=0.02,
                    status_cache_seconds=0, allowed_hosts=["testserver"])


@pytest.fixture
def fake() -> ToyTask:
    return ToyTask()


@pytest.fixture
def client(settings: Settings, fake: ToyTask) -> Iterator[TestClient]:
    """The API and, beside it, a scheduler thread that evaluates the toy fitness."""
    with TestClient(create_app(settings)) as c, running_scheduler(settings, fake):
        yield c
