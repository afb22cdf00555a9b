"""The engine's facade: every name resolves, names load lazily, type checkers see the same names."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import finaldrive.engine as engine


def test_every_exported_name_resolves() -> None:
    for name in engine.__all__:
        assert getattr(engine, name) is not None, name


def test_the_type_checking_block_names_exactly_the_lazy_exports() -> None:
    tree = ast.parse(Path(engine.__file__).read_text())
    block = next(n for n in tree.body if isinstance(n, ast.If) and ast.unparse(n.test) == "TYPE_CHECKING")
    seen = {alias.name: node.module for node in block.body if isinstance(node, ast.ImportFrom)
            for alias in node.names if alias.asname == alias.name}
    assert seen == engine._EXPORTS


def test_importing_the_facade_loads_no_simulation_machinery() -> None:
    code = ("import sys, finaldrive.engine as e; e.Bounds; e.DESettings; e.PRESETS; "
            "assert not {'numba', 'scipy'} & set(sys.modules), sorted({'numba', 'scipy'} & set(sys.modules))")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_the_geometry_command_loads_no_simulation_machinery() -> None:
    """`finaldrive geometry` (no --travel) answers from kinematics alone: no numba, no solver."""
    code = ("import sys; from finaldrive.service.cli import main; "
            "assert main(['geometry', '--a2-deg', '195.3', '--l2-m', '0.037', '--rws-m', '0.088', '--json']) == 0; "
            "heavy = {'numba', 'finaldrive.engine.simulation', 'finaldrive.engine.solver.reference'} "
            "& set(sys.modules); assert not heavy, sorted(heavy)")
    subprocess.run([sys.executable, "-c", code], check=True, stdout=subprocess.DEVNULL)
