"""Real processes for end-to-end tests: ``finaldrive serve`` and ``finaldrive scheduler``."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import psutil

from finaldrive.service.machine import free_port


def console_script(name: str) -> str:
    """The installed console script ``name``: beside this interpreter (a venv not activated), else on PATH."""
    beside = Path(sys.executable).parent / name
    found = str(beside) if beside.is_file() else shutil.which(name)
    assert found, f"the {name} console script is not installed (pip install -e .)"
    return found


class Proc:
    """A finaldrive command in a child process, its output appended to ``log``."""

    def __init__(self, args: list[str], log: Path, env: dict[str, str] | None = None) -> None:
        self.args = args
        self.log = log
        self.env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", **(env or {})}
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> Proc:
        with self.log.open("ab") as out:
            self.proc = subprocess.Popen([sys.executable, "-m", "finaldrive.service.cli", *self.args], env=self.env,
                                         stdout=out, stderr=subprocess.STDOUT)
        return self

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def descendants(self) -> list[psutil.Process]:
        try:
            return psutil.Process(self.pid).children(recursive=True)
        except psutil.NoSuchProcess:
            return []

    def kill(self) -> None:
        """SIGKILL, as a crash would."""
        if self.alive():
            assert self.proc is not None
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(10)

    def terminate(self, timeout: float = 30.0) -> int:
        """SIGTERM, as a normal stop; returns the exit code."""
        assert self.proc is not None
        if self.alive():
            self.proc.send_signal(signal.SIGTERM)
        return self.proc.wait(timeout)


class Server(Proc):
    """``finaldrive serve`` on a free loopback port (with its scheduler, unless ``--no-scheduler``)."""

    def __init__(self, db_url: str, log: Path, *extra: str, env: dict[str, str] | None = None) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        super().__init__(["serve", "--port", str(self.port), "--db", db_url, *extra], log, env)

    def start(self) -> Server:
        super().start()
        token = self.env.get("FINALDRIVE_API_TOKEN")
        headers = {"Authorization": f"Bearer {token}"} if token else {}
        self.client = httpx.Client(base_url=self.url, timeout=30, headers=headers)
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            assert self.alive(), self.log.read_text()[-5000:]
            try:  # healthy; an API without its own scheduler: answering is enough
                if self.client.get("/v1/health").status_code == 200 or "--no-scheduler" in self.args:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.1)
        raise AssertionError("server did not become healthy:\n" + self.log.read_text()[-5000:])
