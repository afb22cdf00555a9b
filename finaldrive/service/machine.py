"""What machine this is, for benchmark output and reports."""

from __future__ import annotations

import os
import platform
import socket
from pathlib import Path


def cpu_model() -> str:
    """The CPU's model name (from /proc/cpuinfo where there is one)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def describe(load: bool = True) -> str:
    """One line: CPU, cores, OS, Python and (optionally) the load average now."""
    text = (f"{cpu_model()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}")
    if load and hasattr(os, "getloadavg"):
        text += ", load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    return text


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now (for a server this process is about to start)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
