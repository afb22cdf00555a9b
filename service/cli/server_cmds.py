"""``finaldrive serve`` and ``finaldrive db upgrade``.

The web and database stacks are imported inside the command functions, so other commands
do not pay for them.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from service.config import Settings


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    serve = subparsers.add_parser("serve", help="run the REST job service")
    serve.add_argument("--host", help="interface to bind (default 127.0.0.1, FINALDRIVE_HOST)")
    serve.add_argument("--port", type=int, help="port (default 8000, FINALDRIVE_PORT)")
    serve.add_argument("--db", metavar="URL", help="SQLAlchemy URL (default sqlite:///./finaldrive.db)")
    serve.add_argument("--executor", choices=("serial", "process", "ray"), help="where simulations run")
    serve.set_defaults(run=run_serve)

    db = subparsers.add_parser("db", help="manage the results database")
    db_sub = db.add_subparsers(dest="db_command", required=True)
    upgrade = db_sub.add_parser("upgrade", help="migrate the database schema to this version")
    upgrade.add_argument("--db", metavar="URL", help="SQLAlchemy URL (default: FINALDRIVE_DB_URL or ./finaldrive.db)")
    upgrade.set_defaults(run=run_db_upgrade)


def _settings(args: argparse.Namespace) -> Settings:
    from service.config import Settings

    overrides = {
        "db_url": getattr(args, "db", None), "host": getattr(args, "host", None),
        "port": getattr(args, "port", None), "executor": getattr(args, "executor", None),
    }
    return Settings(**{k: v for k, v in overrides.items() if v is not None})


def run_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from service.db.migrate import SchemaMismatchError
    from service.main import create_app
    from service.services import open_database

    settings = _settings(args)
    try:  # fail fast, with one line, before uvicorn starts
        open_database(settings).dispose()
    except SchemaMismatchError as exc:
        print(f"finaldrive: error: {exc}", file=sys.stderr)
        return 1
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, workers=1)
    return 0


def run_db_upgrade(args: argparse.Namespace) -> int:
    from service.db.migrate import head_revision, upgrade

    url = _settings(args).db_url
    upgrade(url)
    print(f"database {url} is at schema revision {head_revision()}")
    return 0
