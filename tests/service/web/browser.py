"""A browser tab for the dashboard's tests (the fixtures are in conftest.py)."""

from __future__ import annotations

import os
import shutil
from typing import Any

from tests.service.processes import Server

#: the test server's FINALDRIVE_API_TOKEN
TOKEN = "dashboard-test-token"


def chromium() -> str | None:
    return os.environ.get("FINALDRIVE_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")


class Page:
    """A browser tab on the server that records every request the page (and its frames) makes, and signs in as
    the sign-in page does (``POST /v1/session``: the server sets the HttpOnly cookie)."""

    def __init__(self, browser: Any, server: Server, signed_in: bool) -> None:
        self.base = server.url
        self.context = browser.new_context(viewport={"width": 1400, "height": 1000})
        if signed_in:
            answer = self.context.request.post(self.base + "/v1/session", data={"token": TOKEN})
            assert answer.status == 204, answer.text()
        self.page = self.context.new_page()
        self.requests: list[str] = []
        self.errors: list[str] = []
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))

    def goto(self, path: str) -> Any:
        return self.page.goto(self.base + path)

    def ready(self, timeout_s: float = 60) -> None:
        self.page.wait_for_selector("body[data-ready]", timeout=timeout_s * 1000)

    def foreign_requests(self) -> list[str]:
        return [u for u in self.requests if not u.startswith((self.base + "/", "blob:" + self.base, "data:"))]
