"""Browser fixtures: a real ``finaldrive serve`` with a token on 127.0.0.1 and the system's headless Chromium
(Playwright), and a signed-in tab that records every request its pages make."""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

import pytest

from tests.service.processes import Server
from tests.service.web.browser import TOKEN, Page, chromium


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    tmp = tmp_path_factory.mktemp("dashboard")
    srv = Server(f"sqlite:///{tmp / 'fd.db'}", tmp / "serve.log", "--executor", "serial",
                 env={"FINALDRIVE_API_TOKEN": TOKEN}).start()
    try:
        yield srv
    finally:
        srv.terminate()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    executable = chromium()
    if executable is None:
        reason = "Chromium not found; install Debian's chromium (as .ci/run does) or set FINALDRIVE_CHROMIUM"
        if os.environ.get("FINALDRIVE_REQUIRE_CHROMIUM"):
            pytest.fail(reason)
        pytest.skip(reason)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=executable, args=[
            "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
            "--disable-sync", "--no-first-run"])
        try:
            yield b
        finally:
            b.close()


@pytest.fixture
def tab(browser: Any, server: Server) -> Iterator[Page]:
    page = Page(browser, server, signed_in=True)
    yield page
    page.context.close()
    assert page.foreign_requests() == [], "the page asked for something off this server"
    assert page.errors == [], page.errors
