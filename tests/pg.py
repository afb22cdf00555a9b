"""A throwaway PostgreSQL server for the tests, started from the machine's binaries (initdb, pg_ctl).

The cluster lives in a temporary directory, listens on 127.0.0.1 and a free port, trusts local
connections and is stopped (and deleted) at the end of the session. As root, the server runs as
the ``postgres`` user (initdb refuses root). Without PostgreSQL binaries the tests that need it
are skipped with that reason; CI installs Debian's ``postgresql`` (.ci/run).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import time
import uuid
from pathlib import Path

from finaldrive.service.machine import free_port


def bindir() -> Path | None:
    """The directory holding initdb and pg_ctl: from PATH, else the newest under /usr/lib/postgresql."""
    found = shutil.which("initdb")
    if found and shutil.which("pg_ctl"):
        return Path(os.path.realpath(found)).parent
    versions = sorted(Path("/usr/lib/postgresql").glob("*/bin/initdb"), key=lambda p: int(p.parts[-3]))
    return versions[-1].parent if versions else None


class PostgresServer:
    """One cluster; :meth:`new_database` gives each test a database of its own."""

    def __init__(self, binaries: Path) -> None:
        self.bin = binaries
        self.port = free_port()
        self.dir = Path(tempfile.mkdtemp(prefix="finaldrive-pg-"))
        self.data = self.dir / "data"
        self._as_postgres = os.geteuid() == 0
        if self._as_postgres:
            shutil.chown(self.dir, "postgres", "postgres")

    def _run(self, *args: str) -> None:
        cmd = [str(self.bin / args[0]), *args[1:]]
        if self._as_postgres:
            cmd = ["runuser", "-u", "postgres", "--", *cmd]
        subprocess.run(cmd, check=True, capture_output=True, timeout=120)

    def start(self) -> PostgresServer:
        self._run("initdb", "-D", str(self.data), "-A", "trust", "-U", "postgres", "--no-sync", "-E", "UTF8")
        self._start()
        return self

    def _start(self) -> None:
        # fsync off: a crash of the server (below) loses nothing a commit flushed to the OS; only a crash of
        # the machine would, which these tests do not make
        options = f"-p {self.port} -k {self.dir} -c listen_addresses=127.0.0.1 -c fsync=off -c max_connections=200"
        self._run("pg_ctl", "-D", str(self.data), "-o", options, "-l", str(self.dir / "log"), "-w", "start")

    def crash(self, *, kill: bool = False) -> None:
        """Crash the server and start it again: ``pg_ctl restart -m immediate`` (every process quits
        without a checkpoint; recovery replays the WAL), or with ``kill`` SIGKILL of the postmaster."""
        if not kill:  # pg_ctl restart would start the server without its log file (-l), on our pipes
            self._run("pg_ctl", "-D", str(self.data), "-m", "immediate", "-w", "stop")
            self._start()
            return
        postmaster = int((self.data / "postmaster.pid").read_text().split()[0])
        os.kill(postmaster, signal.SIGKILL)
        deadline = time.monotonic() + 30  # its backends notice and quit; then the shared memory is free
        while time.monotonic() < deadline:
            try:
                self._start()
                return
            except subprocess.CalledProcessError:
                time.sleep(0.2)
        self._start()

    def stop(self) -> None:
        try:
            self._run("pg_ctl", "-D", str(self.data), "-m", "immediate", "-w", "stop")
        finally:
            shutil.rmtree(self.dir, ignore_errors=True)

    def url(self, database: str = "postgres") -> str:
        return f"postgresql+psycopg://postgres@127.0.0.1:{self.port}/{database}"

    def new_database(self) -> str:
        """A fresh empty database; returns its SQLAlchemy URL."""
        import psycopg

        name = f"t_{uuid.uuid4().hex[:12]}"
        with psycopg.connect(f"postgresql://postgres@127.0.0.1:{self.port}/postgres", autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)
