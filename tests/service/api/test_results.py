"""/v1/jobs/{id}/evaluations: CSV pages stream rows in chunks; JSON pages are capped."""

from __future__ import annotations

import csv
import io

import pytest
from fastapi.testclient import TestClient

from finaldrive.service.api.routes import results
from finaldrive.service.db import columns
from tests.service.svc_helpers import SWEEP, wait_done


def test_csv_pages_stream_the_same_rows_as_json(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(columns, "CHUNK_ROWS", 5)  # several chunks a page
    job = wait_done(client, client.post("/v1/jobs", json=SWEEP).json()["id"])
    url = f"/v1/jobs/{job['id']}/evaluations"
    items = client.get(url).json()["items"]
    rows, cursor, pages = [], None, 0
    while True:
        r = client.get(url, params={"format": "csv", "limit": 7, **({"cursor": cursor} if cursor else {})})
        assert r.headers["content-type"].startswith("text/csv")
        page = list(csv.DictReader(io.StringIO(r.text)))
        assert 0 < len(page) <= 7 and list(page[0]) == list(results.CSV_COLUMNS)
        rows += page
        pages += 1
        cursor = r.headers["x-next-cursor"]
        if not cursor:
            break
    assert pages == 4 and len(rows) == len(items) == 24
    for row, item in zip(rows, items, strict=True):
        assert row == {k: "" if v is None else str(v) for k, v in item.items()}
    on_road = client.get(url, params={"format": "csv", "road": "flat", "limit": 100})
    assert on_road.text.count("\n") == 13 and on_road.headers["x-next-cursor"] == ""


def test_json_pages_are_capped(client: TestClient) -> None:
    job = client.post("/v1/jobs", json=SWEEP).json()
    url = f"/v1/jobs/{job['id']}/evaluations"
    r = client.get(url, params={"limit": 10_001})
    assert r.status_code == 422 and "format=csv" in r.json()["detail"]
    assert client.get(url, params={"limit": 10_000}).status_code == 200
    assert client.get(url, params={"limit": 100_000, "format": "csv"}).status_code == 200
    assert client.get("/v1/jobs/999/evaluations", params={"format": "csv"}).status_code == 404
