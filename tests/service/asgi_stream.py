"""A request run on a TestClient's event loop and read while it streams.

Starlette's TestClient returns a response only once the app has sent all of it, so an endless
stream (server-sent events) never returns; :class:`AsgiStream` calls the app itself, in the
TestClient's loop, keeps what it sends, and disconnects on :meth:`close`.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import anyio
from fastapi.testclient import TestClient


class AsgiStream:
    def __init__(self, client: TestClient, path: str, *, method: str = "GET", headers: dict[str, str] | None = None,
                 client_host: str = "127.0.0.1", host: str = "testserver") -> None:
        path, _, query = path.partition("?")
        all_headers = {"host": host, **(headers or {})}
        self.scope: dict[str, Any] = {
            "type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": method, "scheme": "http",
            "path": path, "raw_path": path.encode(), "query_string": query.encode(), "root_path": "",
            "headers": [(k.lower().encode(), v.encode()) for k, v in all_headers.items()],
            "client": (client_host, 40000), "server": ("testserver", 80)}
        self.status: int | None = None
        self.headers: dict[str, str] = {}
        self.body = bytearray()
        self.ended = threading.Event()
        self._started = threading.Event()
        self._closing = threading.Event()
        self._asked = False
        assert client.portal is not None, "use the TestClient as a context manager"
        self._future = client.portal.start_task_soon(self._run, client.app)

    async def _run(self, app: Any) -> None:
        try:
            await app(self.scope, self._receive, self._send)
        finally:
            self.ended.set()
            self._started.set()

    async def _receive(self) -> dict[str, Any]:
        if not self._asked:
            self._asked = True
            return {"type": "http.request", "body": b"", "more_body": False}
        while not self._closing.is_set():
            await anyio.sleep(0.005)
        return {"type": "http.disconnect"}

    async def _send(self, message: dict[str, Any]) -> None:
        if message["type"] == "http.response.start":
            self.status = message["status"]
            self.headers = {k.decode().lower(): v.decode() for k, v in message.get("headers", [])}
            self._started.set()
        elif message["type"] == "http.response.body":
            self.body += message.get("body", b"")

    def started(self, timeout: float = 10.0) -> int:
        """The status, once the answer has begun."""
        assert self._started.wait(timeout), "no answer"
        assert self.status is not None
        return self.status

    def wait_for(self, text: str, timeout: float = 10.0) -> str:
        """The body so far, once it contains ``text``."""
        deadline = time.monotonic() + timeout
        while text not in self.text:
            assert time.monotonic() < deadline and not self.ended.is_set(), self.text
            time.sleep(0.005)
        return self.text

    @property
    def text(self) -> str:
        return self.body.decode(errors="replace")

    def close(self, timeout: float = 10.0) -> None:
        """Disconnect, and wait for the app to finish the request."""
        self._closing.set()
        self._future.result(timeout)
