"""Request body size limit answering 413 as a problem document.

Starlette 1.10's ``RequestBodyLimitMiddleware`` answers an over-long declared body with a
plain-text 413; this one keeps every error a problem document. The limit is read from the
running app's settings, which exist only once the lifespan has started.
"""

from __future__ import annotations

from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from finaldrive.service.api.problems import problem_response


class BodySizeLimit:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit: int = scope["app"].state.services.settings.max_body_bytes
        detail = f"request body larger than {limit} bytes"
        declared = Request(scope).headers.get("content-length", "").lstrip("0")
        # the length compared before int(), which refuses more than 4,300 digits
        if declared.isascii() and declared.isdigit() and (len(declared) > len(str(limit)) or int(declared) > limit):
            await problem_response(Request(scope), 413, detail)(scope, receive, send)
            return
        seen = 0

        async def limited_receive() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > limit:
                    raise HTTPException(413, detail)
            return message

        await self.app(scope, limited_receive, send)
