"""One import package, in finaldrive/: finaldrive.{engine,workers,service,migrations}, the top-level folders
of those names links into it; nothing importable under the folders' own names."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
FOLDERS = ("engine", "workers", "service", "migrations")


@pytest.mark.parametrize("name", FOLDERS)
def test_the_folders_are_not_importable_under_their_own_names(name: str, tmp_path: Path) -> None:
    for cwd in (REPO, tmp_path):  # from the clone (its folders are on sys.path) and from anywhere else
        done = subprocess.run([sys.executable, "-c", f"import {name}"], cwd=cwd, capture_output=True, text=True)
        assert done.returncode != 0
        assert "ModuleNotFoundError" in done.stderr or f"this is finaldrive.{name}" in done.stderr
    done = subprocess.run([sys.executable, "-c", f"import finaldrive.{name}"], cwd=tmp_path, capture_output=True)
    assert done.returncode == 0, done.stderr


def test_every_package_folder_is_listed_in_pyproject() -> None:
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "package-dir" not in config   # the folders are where the names say: tools read them as they are
    package = REPO / "finaldrive"
    found = {
        ".".join(path.relative_to(REPO).parts) for path in [package, *package.rglob("*")]
        if path.is_dir() and "__pycache__" not in path.parts and any(path.glob("*.py"))
    }
    assert found == set(config["packages"])


@pytest.mark.parametrize("name", FOLDERS)
def test_the_top_level_folders_are_links_to_the_subpackages(name: str) -> None:
    link = REPO / name
    assert link.is_symlink() and link.readlink() == Path("finaldrive") / name
    assert (REPO / "finaldrive" / name).is_dir() and not (REPO / "finaldrive" / name).is_symlink()


@pytest.mark.slow
def test_the_wheel_carries_the_data_and_the_migrations(tmp_path: Path) -> None:
    source = tmp_path / "src"  # a copy of the tracked files: the build writes into its source tree
    tracked = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    for name in tracked:
        (source / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / name, source / name, follow_symlinks=False)   # the top-level links as links
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(source)],
                   check=True, capture_output=True)
    (wheel,) = tmp_path.glob("finaldrive-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {"finaldrive/engine/data/vehicle.json", "finaldrive/engine/data/paper_tables.json",
            "finaldrive/migrations/alembic.ini", "finaldrive/migrations/env.py"} <= names
    assert any(n.startswith("finaldrive/migrations/versions/") for n in names)
    assert not any(n.split("/")[0] in FOLDERS for n in names)


def _locked(path: Path) -> dict[str, str]:
    """A pip-compile lock file's pins: {normalised name: version}."""
    import re

    pins = {}
    for line in path.read_text().splitlines():
        found = re.match(r"^([A-Za-z0-9._-]+)==([^ \\]+)", line)
        if found:
            pins[re.sub(r"[-_.]+", "-", found[1]).lower()] = found[2]
    return pins


@pytest.mark.parametrize(("lock", "extras"), [("requirements.lock", ()), ("requirements-test.lock", ("test",))])
def test_the_lock_files_pin_every_dependency_within_pyproject(lock: str, extras: tuple[str, ...]) -> None:
    """deploy/*.lock (what .ci/locked and the container image install) in step with pyproject.toml:
    every direct dependency pinned, inside its declared range, and the runtime pins the same in both."""
    from packaging.requirements import Requirement

    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    pins = _locked(REPO / "deploy" / lock)
    wanted = [*project["dependencies"], *(d for extra in extras for d in project["optional-dependencies"][extra])]
    for text in wanted:
        requirement = Requirement(text)
        name = requirement.name.lower().replace("_", "-")
        assert name in pins, f"{lock} does not pin {name} (re-run pip-compile: deploy/requirements.lock's header)"
        assert requirement.specifier.contains(pins[name], prereleases=True), f"{lock}: {name}=={pins[name]} {text}"
    runtime = _locked(REPO / "deploy" / "requirements.lock")
    assert {name: pins[name] for name in runtime} == runtime


def test_the_api_reference_lists_exactly_the_engine_facades_names() -> None:
    """docs/reference/engine.md (the site's API reference, mkdocs.yml) documents each name of the facade
    finaldrive.engine under the module the facade loads it from, and nothing else."""
    import re

    import finaldrive.engine as facade

    page = (REPO / "docs" / "reference" / "engine.md").read_text()
    listed: dict[str, str] = {}
    for block in re.split(r"^::: ", page, flags=re.MULTILINE)[1:]:
        module = block.split()[0]
        members = re.search(r"^ +members:\n((?: +- \w+\n?)+)", block, flags=re.MULTILINE)
        assert members, f"docs/reference/engine.md: ::: {module} lists no members"
        for name in re.findall(r"- (\w+)", members.group(1)):
            assert name not in listed, f"docs/reference/engine.md lists {name} twice"
            listed[name] = module
    assert listed == {"ENGINE_VERSION": "finaldrive.engine", **facade._EXPORTS}
