"""A bound on a request's head (request line and headers) for the uvicorn that ``finaldrive serve`` runs.

uvicorn's httptools protocol (httptools is a dependency of finaldrive) keeps a header however long it
is: one request with a 200 MB header held 200 MB of the server's memory, before any check of the
token could run. :class:`BoundedHttpTools` answers 431 and closes the connection once a head passes
:data:`MAX_HEAD_BYTES` (memory then stays below that plus one read of the socket), and answers what
httptools cannot parse (e.g. a Content-Length of 5,000 digits) with a 400 problem document rather than
uvicorn's plain text. (uvicorn's h11 protocol bounds only an incomplete head: a complete one of any
size passes.)
"""

from __future__ import annotations

import json
from http import HTTPStatus
from typing import Any

#: The most bytes a request's head may have (nginx's default allows 32 KiB of headers, h11's 16 KiB).
MAX_HEAD_BYTES = 64 * 1024


class HeadTooLarge(Exception):
    """Raised from the parser's callbacks to stop it."""


def _refusal(status: int, slug: str, detail: str) -> bytes:
    """A whole HTTP response with a problem document, for a request the app never sees."""
    title = HTTPStatus(status).phrase
    body = json.dumps({"type": f"urn:finaldrive:problem:{slug}", "title": title, "status": status,
                       "detail": detail}).encode()
    return (f"HTTP/1.1 {status} {title}\r\ncontent-type: application/problem+json\r\n"
            f"content-length: {len(body)}\r\nconnection: close\r\n\r\n").encode() + body


def server_options() -> dict[str, Any]:
    """Keyword arguments of ``uvicorn.run`` bounding request heads to MAX_HEAD_BYTES."""
    from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol  # httptools: a dependency of finaldrive

    class BoundedHttpTools(HttpToolsProtocol):
        """httptools, counting a head twice: its parsed parts (the URL, each header), and the raw bytes of
        every read that leaves it incomplete (httptools holds a header until its end)."""

        _head_bytes = _raw_bytes = 0
        _in_head = _refused = False

        def on_message_begin(self) -> None:
            super().on_message_begin()
            self._in_head, self._head_bytes, self._raw_bytes = True, 0, 0

        def on_url(self, url: bytes) -> None:
            super().on_url(url)
            self._count(len(url))

        def on_header(self, name: bytes, value: bytes) -> None:
            super().on_header(name, value)
            self._count(len(name) + len(value) + 4)

        def on_headers_complete(self) -> None:
            self._in_head = False
            super().on_headers_complete()

        def _count(self, size: int) -> None:
            self._head_bytes += size
            if self._head_bytes > MAX_HEAD_BYTES:
                self._refused = True
                raise HeadTooLarge  # httptools stops; uvicorn answers with send_400_response, below

        def data_received(self, data: bytes) -> None:
            super().data_received(data)
            if self._in_head and not self.transport.is_closing():
                self._raw_bytes += len(data)
                if self._raw_bytes > MAX_HEAD_BYTES:
                    self._refused = True
                    self.send_400_response("")

        def send_400_response(self, msg: str) -> None:
            """uvicorn's answer to what httptools refuses, as a problem document (431 for a head too long)."""
            if self._refused:
                self.logger.warning("refused a request whose head is over %d bytes", MAX_HEAD_BYTES)
                answer = _refusal(431, "header-too-large",
                                  f"the request line and headers are larger than {MAX_HEAD_BYTES} bytes")
            else:
                answer = _refusal(400, "invalid-http", "the request is not valid HTTP/1.1 (request line, a header "
                                  "such as Content-Length, or the chunked body)")
            self.transport.write(answer)
            self.transport.close()

    return {"http": BoundedHttpTools}
