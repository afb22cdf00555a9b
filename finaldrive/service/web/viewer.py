"""Rerun's web viewer, served at /viewer/ from the installed rerun-sdk (no CDN).

rerun-sdk 0.41 carries its web viewer (index.html, re_viewer.js, re_viewer_bg.wasm) inside its
extension module and hands it out only through its own HTTP server. On first use, a child process
starts that server on a free loopback port, the files are copied into a cache folder named after the
rerun version (next to this module, or in the temporary directory when that is read-only) and the
child stops; the service serves the copies from then on.

The page is changed in one way: the Google Fonts links go (the viewer falls back to its own font).
What the viewer itself would fetch from elsewhere (its update check, telemetry, the examples
manifest) is kept in by the Content-Security-Policy every page of the service carries
(see :mod:`finaldrive.service.web.pages`).
"""

from __future__ import annotations

import importlib.metadata
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

from finaldrive.service.machine import free_port

FILES = ("index.html", "re_viewer.js", "re_viewer_bg.wasm", "favicon.ico")
_FONTS = re.compile(r"<link\b[^>]*?fonts\.(?:googleapis|gstatic)\.com[^>]*?>", re.S)
_lock = threading.Lock()


class ViewerUnavailable(RuntimeError):
    """The installed rerun-sdk could not hand out its web viewer."""


def rerun_version() -> str:
    return importlib.metadata.version("rerun-sdk")


def cache_folder() -> Path:
    here = Path(__file__).parent / "__pycache__"
    base = here if os.access(Path(__file__).parent, os.W_OK) else Path(tempfile.gettempdir()) / "finaldrive"
    return base / f"rerun-web-viewer-{rerun_version()}"


def offline_index(html: str) -> str:
    """The viewer's index.html without links to font servers."""
    return _FONTS.sub("", html)


def assets(timeout: float = 60.0) -> Path:
    """The folder holding the viewer's files, extracted on first call (thread-safe)."""
    folder = cache_folder()
    if (folder / FILES[-1]).exists():
        return folder
    with _lock:
        if not (folder / FILES[-1]).exists():
            _extract(folder, timeout)
    return folder


def _extract(folder: Path, timeout: float) -> None:
    port = free_port()
    child = subprocess.Popen(
        [sys.executable, "-m", "finaldrive.service.web.viewer", str(port)],
        stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    staging = Path(tempfile.mkdtemp(prefix="rerun-web-viewer-", dir=folder.parent if folder.parent.exists() else None))
    try:
        base = f"http://127.0.0.1:{port}/"
        deadline = time.monotonic() + timeout
        with httpx.Client(timeout=timeout) as client:
            for name in FILES:
                while True:
                    try:
                        response = client.get(base + ("" if name == "index.html" else name))
                        break
                    except httpx.TransportError:
                        if child.poll() is not None or time.monotonic() > deadline:
                            err = (child.stderr.read() if child.stderr else b"").decode(errors="replace")
                            raise ViewerUnavailable(f"rerun's web viewer server did not start: {err[-500:]}") from None
                        time.sleep(0.1)
                if response.status_code != 200:
                    raise ViewerUnavailable(f"rerun's web viewer server answered {response.status_code} for {name}")
                body = response.content
                if name == "index.html":
                    body = offline_index(body.decode()).encode()
                (staging / name).write_bytes(body)
        folder.parent.mkdir(parents=True, exist_ok=True)
        try:
            staging.rename(folder)
        except OSError:  # another process got there first
            shutil.rmtree(staging, ignore_errors=True)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
        if child.stdin is not None:
            child.stdin.close()
        try:
            child.wait(10)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()


def _serve(port: int) -> None:
    """Child process: serve the viewer on ``port`` until stdin closes."""
    from finaldrive.service.media.recording import serve_viewer

    serve_viewer(port)
    sys.stdin.read()


if __name__ == "__main__":
    _serve(int(sys.argv[1]))
