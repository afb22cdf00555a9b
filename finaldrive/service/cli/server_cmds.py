"""``finaldrive serve``, ``finaldrive scheduler`` and ``finaldrive db upgrade``.

``serve`` runs the API and, beside it, one scheduler in a child process that it restarts if it
dies and stops with it; ``scheduler`` runs one more scheduler on a database, on this machine or
another. The web, database and Ray stacks are imported inside the command functions.
"""

from __future__ import annotations

import argparse
import logging
import os
import subprocess
import sys
import threading
import time
from typing import TYPE_CHECKING, Any

from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import UsageError, parser_options, stop_process

if TYPE_CHECKING:
    from finaldrive.service.config import Settings

#: Seconds a stopping scheduler gets before it is killed (it cancels its simulations within 2 s).
SCHEDULER_STOP_S = 15.0
#: Back-off between restarts of a scheduler that keeps dying [s].
RESTART_BACKOFF_S = (1.0, 30.0)


def _scheduler_name(value: str) -> str:
    """``--id``: a name the store can hold (schedulers.id)."""
    from finaldrive.service.db.leases import MAX_SCHEDULER_ID

    if not value or len(value) > MAX_SCHEDULER_ID:
        raise argparse.ArgumentTypeError(f"a scheduler id has 1 to {MAX_SCHEDULER_ID} characters, not {len(value)}")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    from finaldrive.service.config import Settings

    defaults = {name: field.default for name, field in Settings.model_fields.items()}
    serve = subparsers.add_parser("serve", help=COMMANDS["serve"].help,
                                  **parser_options())
    serve.add_argument("--host", help=f"interface to bind (default {defaults['host']}; FINALDRIVE_HOST)")
    serve.add_argument("--port", type=int, help=f"port (default {defaults['port']}; FINALDRIVE_PORT)")
    _store_and_executor(serve, defaults)
    serve.add_argument("--no-scheduler", action="store_true",
                       help="serve the API only (schedulers run elsewhere: finaldrive scheduler)")
    serve.set_defaults(run=run_serve)

    scheduler = subparsers.add_parser(
        "scheduler", help=COMMANDS["scheduler"].help,
        description="Several schedulers, on several machines, may serve one database: each job runs under "
                    "one scheduler's lease; a scheduler that dies leaves its jobs to the others once its "
                    "leases lapse. Stop it with SIGTERM or Ctrl-C: it gives its jobs back.", **parser_options())
    _store_and_executor(scheduler, defaults)
    scheduler.add_argument("--workers", type=int, help="worker processes / Ray CPUs (default: all cores; "
                           "FINALDRIVE_NUM_WORKERS)")
    scheduler.add_argument("--id", dest="scheduler_id", type=_scheduler_name,
                           help="this scheduler's name in the store, at most 64 characters (default: "
                           "host:pid:random); a restart with the same id takes its jobs back at once")
    scheduler.add_argument("--exit-with-parent", action="store_true",
                           help="stop (giving the jobs back) when the parent process ends; finaldrive serve uses it")
    scheduler.set_defaults(run=run_scheduler_command)

    db = subparsers.add_parser("db", help=COMMANDS["db"].help, **parser_options())
    db_sub = db.add_subparsers(dest="db_command", required=True, metavar="COMMAND")
    upgrade = db_sub.add_parser("upgrade", help="migrate the database schema to this version", **parser_options())
    upgrade.add_argument("--db", metavar="URL",
                         help=f"SQLAlchemy URL (default {defaults['db_url']}; FINALDRIVE_DB_URL)")
    upgrade.set_defaults(run=run_db_upgrade)


def _store_and_executor(p: argparse.ArgumentParser, defaults: dict[str, Any]) -> None:
    p.add_argument("--db", metavar="URL", help=f"SQLAlchemy URL, e.g. postgresql+psycopg://user@host/db "
                   f"(default {defaults['db_url']}; FINALDRIVE_DB_URL)")
    p.add_argument("--executor", choices=("serial", "process", "ray"),
                   help=f"where simulations run (default {defaults['executor']}; FINALDRIVE_EXECUTOR; "
                        "ray joins RAY_ADDRESS when set)")


def _settings(args: argparse.Namespace) -> Settings:
    from pydantic import ValidationError

    from finaldrive.service.config import Settings

    overrides = {
        "db_url": getattr(args, "db", None), "host": getattr(args, "host", None),
        "port": getattr(args, "port", None), "executor": getattr(args, "executor", None),
        "num_workers": getattr(args, "workers", None),
    }
    try:
        return Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as exc:
        raise UsageError("; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())) from None


def _check_store(settings: Settings) -> None:
    """Fail fast, with one line, when the database is at another schema revision."""
    from finaldrive.service.db.migrate import SchemaMismatchError
    from finaldrive.service.services import open_database

    try:
        open_database(settings).dispose()
    except SchemaMismatchError as exc:
        raise UsageError(str(exc)) from None


# --- serve ---------------------------------------------------------------------------------------

class SchedulerChild:
    """``finaldrive scheduler`` in a child process, restarted when it dies, stopped with ``stop``.

    Its settings go through the environment (FINALDRIVE_*), not its command line, so a database
    password never shows in the process list.
    """

    def __init__(self, args: list[str], env: dict[str, str]) -> None:
        self._args = args
        self._env = env
        self._proc: subprocess.Popen[bytes] | None = None
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._supervise, name="finaldrive-scheduler-supervisor", daemon=True)

    def start(self) -> SchedulerChild:
        self._thread.start()
        return self

    def _supervise(self) -> None:
        delay = RESTART_BACKOFF_S[0]
        while not self._stopping.is_set():
            started = time.monotonic()
            self._proc = subprocess.Popen([sys.executable, "-m", "finaldrive.service.cli", "scheduler", *self._args],
                                          env=self._env)
            code = self._proc.wait()
            if self._stopping.is_set():
                return
            delay = RESTART_BACKOFF_S[0] if time.monotonic() - started > 60 else min(2 * delay, RESTART_BACKOFF_S[1])
            logging.getLogger(__name__).warning("the scheduler exited with code %s; restarting in %.0f s", code, delay)
            self._stopping.wait(delay)

    def stop(self) -> None:
        self._stopping.set()
        if self._proc is not None:
            stop_process(self._proc, SCHEDULER_STOP_S)
        self._thread.join(SCHEDULER_STOP_S)


#: At shutdown, how long open requests (a dashboard's event streams) may take to end before they are
#: cancelled [s]: some uvicorn versions (0.30) wait for an open event stream without end.
GRACEFUL_SHUTDOWN_S = 5


def run_serve(args: argparse.Namespace) -> int:
    settings = _settings(args)
    _check_store(settings)
    child = None
    if not args.no_scheduler:
        if settings.executor != "serial":
            from finaldrive.engine import compile_engine

            compile_engine()   # now, so it overlaps the start of the app and of the scheduler's pool
        from finaldrive.service.db.leases import scheduler_id

        env = {**os.environ, "FINALDRIVE_DB_URL": settings.db_url, "FINALDRIVE_EXECUTOR": settings.executor}
        # the same id across restarts: a restarted scheduler takes its jobs back at once
        child = SchedulerChild(["--id", scheduler_id(f"serve-{os.uname().nodename}", f"-{os.getpid()}"),
                                "--exit-with-parent"], env).start()
    try:
        import uvicorn  # after the scheduler's start, which takes longer (Ray's start)

        from finaldrive.service.api.head_limit import server_options
        from finaldrive.service.main import create_app

        uvicorn.run(create_app(settings), host=settings.host, port=settings.port, workers=1,
                    timeout_graceful_shutdown=GRACEFUL_SHUTDOWN_S, **server_options())
    finally:
        if child is not None:
            child.stop()
    return 0


# --- scheduler -----------------------------------------------------------------------------------

def run_scheduler_command(args: argparse.Namespace) -> int:
    from finaldrive.service.jobs.scheduler import run_scheduler

    settings = _settings(args)
    _check_store(settings)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    stop = threading.Event()
    if args.exit_with_parent:
        threading.Thread(target=_stop_with_parent, args=(os.getppid(), stop), daemon=True,
                         name="finaldrive-parent-watch").start()
    from finaldrive.workers import ClusterTaken, NotOnCluster

    try:
        run_scheduler(settings, stop, scheduler_id=args.scheduler_id, handle_signals=True)
    except NotOnCluster as exc:
        raise UsageError(str(exc)) from None
    except ClusterTaken:
        if not stop.is_set():
            raise
        logging.getLogger(__name__).info("the standby scheduler stopped before it took the Ray cluster over")
    return 0


def _stop_with_parent(parent: int, stop: threading.Event) -> None:
    """Set ``stop`` once the parent process has ended (this process was re-parented; checked twice a second)."""
    while not stop.wait(0.5):
        if os.getppid() != parent:
            stop.set()


def run_db_upgrade(args: argparse.Namespace) -> int:
    from finaldrive.service.db.engine import display_url
    from finaldrive.service.db.migrate import MigrationBusyError, head_revision, upgrade

    url = _settings(args).db_url
    try:
        upgrade(url)
    except MigrationBusyError as exc:
        raise UsageError(str(exc)) from None
    print(f"database {display_url(url)} is at schema revision {head_revision()}")
    return 0
