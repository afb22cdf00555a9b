"""``finaldrive serve`` and ``finaldrive db upgrade``.

The web and database stacks are imported inside the command functions, so other commands
do not pay for them.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from finaldrive.service.cli.common import parser_options

if TYPE_CHECKING:
    from finaldrive.service.config import Settings


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from finaldrive.service.config import Settings

    defaults = {name: field.default for name, field in Settings.model_fields.items()}
    serve = subparsers.add_parser("serve", help="run the REST job service", **parser_options())
    serve.add_argument("--host", help=f"interface to bind (default {defaults['host']}; FINALDRIVE_HOST)")
    serve.add_argument("--port", type=int, help=f"port (default {defaults['port']}; FINALDRIVE_PORT)")
    serve.add_argument("--db", metavar="URL", help=f"SQLAlchemy URL (default {defaults['db_url']}; FINALDRIVE_DB_URL)")
    serve.add_argument("--executor", choices=("serial", "process", "ray"),
                       help=f"where simulations run (default {defaults['executor']}; FINALDRIVE_EXECUTOR)")
    serve.set_defaults(run=run_serve)

    db = subparsers.add_parser("db", help="manage the results database", **parser_options())
    db_sub = db.add_subparsers(dest="db_command", required=True, metavar="COMMAND")
    upgrade = db_sub.add_parser("upgrade", help="migrate the database schema to this version", **parser_options())
    upgrade.add_argument(
        "--db", metavar="URL", help=f"SQLAlchemy URL (default {defaults['db_url']}; FINALDRIVE_DB_URL)"
    )
    upgrade.set_defaults(run=run_db_upgrade)


def _settings(args: argparse.Namespace) -> Settings:
    from finaldrive.service.config import Settings

    overrides = {
        "db_url": getattr(args, "db", None), "host": getattr(args, "host", None),
        "port": getattr(args, "port", None), "executor": getattr(args, "executor", None),
    }
    return Settings(**{k: v for k, v in overrides.items() if v is not None})


def run_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from finaldrive.service.db.migrate import SchemaMismatchError
    from finaldrive.service.main import create_app
    from finaldrive.service.services import open_database

    settings = _settings(args)
    try:  # fail fast, with one line, before uvicorn starts
        open_database(settings).dispose()
    except SchemaMismatchError as exc:
        print(f"finaldrive: error: {exc}", file=sys.stderr)
        return 1
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, workers=1)
    return 0


def run_db_upgrade(args: argparse.Namespace) -> int:
    from finaldrive.service.db.engine import display_url
    from finaldrive.service.db.migrate import head_revision, upgrade

    url = _settings(args).db_url
    upgrade(url)
    print(f"database {display_url(url)} is at schema revision {head_revision()}")
    return 0
