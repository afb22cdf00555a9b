"""Shared fixtures: the paper's tables (from ../shared, the source of truth) and the vehicle."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from engine import default_vehicle

REPO = Path(__file__).resolve().parents[1]
SHARED_TABLES = REPO.parent / "shared" / "paper" / "tables.json"
SHIPPED_TABLES = REPO / "engine" / "data" / "paper_tables.json"


@pytest.fixture(scope="session")
def tables() -> dict:
    path = SHARED_TABLES if SHARED_TABLES.exists() else SHIPPED_TABLES
    return json.loads(path.read_text())


@pytest.fixture(scope="session")
def vehicle():
    return default_vehicle()
