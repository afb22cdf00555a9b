"""Shared fixtures: the paper's tables (as shipped in engine/data) and the vehicle."""

from __future__ import annotations

import pytest

from finaldrive.engine import default_vehicle, paper_tables


@pytest.fixture(scope="session")
def tables() -> dict:
    return paper_tables()


@pytest.fixture(scope="session")
def vehicle():
    return default_vehicle()
