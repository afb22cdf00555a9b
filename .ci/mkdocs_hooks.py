"""mkdocs hook (mkdocs.yml's `hooks`): lets mkdocstrings find the package's sources for the API reference.

The import package finaldrive has no folder of its own (pyproject.toml's package-dir maps finaldrive.engine to
engine/, and so on), so griffe, which reads sources from disk, finds no finaldrive/ to read. As .ci/check does for
mypy and import-linter, this builds a link tree for the build (finaldrive/engine -> engine/, ...) and points the
python handler at it; the tree is removed when mkdocs ends.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

from mkdocs.plugins import event_priority

PACKAGES = ("engine", "workers", "service", "migrations")
_trees: list[Path] = []


@event_priority(100)  # before mkdocstrings makes its handlers
def on_config(config: Any) -> Any:
    root = Path(config.config_file_path).resolve().parent
    tree = Path(tempfile.mkdtemp(prefix="finaldrive-docs-"))
    _trees.append(tree)
    (tree / "finaldrive").mkdir()
    for package in PACKAGES:
        (tree / "finaldrive" / package).symlink_to(root / package, target_is_directory=True)
    python = config.plugins["mkdocstrings"].config.handlers.setdefault("python", {})
    python["paths"] = [str(tree)]
    return config


def on_shutdown() -> None:
    for tree in _trees:
        shutil.rmtree(tree, ignore_errors=True)
