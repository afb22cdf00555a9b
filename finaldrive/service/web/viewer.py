"""Rerun's web viewer, served at /viewer/ from the installed rerun-sdk (no CDN).

rerun-sdk 0.41 carries its web viewer (index.html, re_viewer.js, re_viewer_bg.wasm) inside its
extension module and hands it out only through its own HTTP server. On first use, a child process
starts that server on a free loopback port, the files are copied into a cache folder named after the
rerun version (next to this module, or in the temporary directory when that is read-only) and the
child stops; the service serves the copies from then on.

The page is changed in two ways: the Google Fonts links go (the viewer falls back to its own font), and
the viewer's handle is left on its window as ``finaldriveViewer`` as soon as it is made, so that the
design page can start the viewer (seconds of wasm and shaders) while its designs are simulated and hand
it the recording's bytes later, through a channel (``open_channel``, ``send_rrd_to_channel``: the
viewer takes them while it is still starting; a receiver added by URL, ``add_receiver``, is lost then, and
after the start it drew seconds later than the channel in headless Chromium). The copies' folder is named after the
rerun version and :data:`REWRITE`, so a change of either extracts them anew.
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
_HANDLE = "let handle = new wasm_bindgen.WebHandle(options);"
#: The version of :func:`offline_index`'s changes (part of the copies' folder name).
REWRITE = 4
_lock = threading.Lock()


class ViewerUnavailable(RuntimeError):
    """The installed rerun-sdk could not hand out its web viewer."""


def rerun_version() -> str:
    return importlib.metadata.version("rerun-sdk")


def cache_folder() -> Path:
    here = Path(__file__).parent / "__pycache__"
    base = here if os.access(Path(__file__).parent, os.W_OK) else Path(tempfile.gettempdir()) / "finaldrive"
    return base / f"rerun-web-viewer-{rerun_version()}-{REWRITE}"


def offline_index(html: str) -> str:
    """The viewer's index.html without links to font servers, its handle on its window (when the page
    makes it as rerun 0.41's does; otherwise the design page loads the viewer with the recording's URL)."""
    return _FONTS.sub("", html).replace(_HANDLE, _HANDLE + " window.finaldriveViewer = handle;")


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
