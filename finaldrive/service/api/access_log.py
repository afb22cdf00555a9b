"""The access log without query strings: they may carry secrets (a ``?token=`` a client sent).

uvicorn's access logger (``uvicorn.access``) logs each request as ``client - "METHOD PATH?QUERY HTTP/v"
status``, its arguments a tuple; :class:`PathOnly` cuts the path at its ``?`` before any handler
formats the record (a path's own ``?`` is percent-encoded, so the first one starts the query).
"""

from __future__ import annotations

import logging

ACCESS_LOGGER = "uvicorn.access"


class PathOnly(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args
        if isinstance(args, tuple) and len(args) == 5 and isinstance(args[2], str) and "?" in args[2]:
            record.args = (args[0], args[1], args[2].split("?", 1)[0], args[3], args[4])
        return True


def install() -> None:
    """Add :class:`PathOnly` to uvicorn's access logger (once)."""
    logger = logging.getLogger(ACCESS_LOGGER)
    if not any(isinstance(f, PathOnly) for f in logger.filters):
        logger.addFilter(PathOnly())
