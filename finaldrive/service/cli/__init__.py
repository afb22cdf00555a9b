"""finaldrive: motorcycle final-drive geometry by multibody simulation on uneven roads.

The command line. Each command group lives in its own module exposing ``register(subparsers)``;
``main`` wires them together. Bad arguments and unreadable or unwritable files exit with code 2
and one line on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence
from typing import Any, NoReturn

from finaldrive.service.cli.commands import COMMANDS
from finaldrive.service.cli.common import UsageError, parser_options

#: Modules that add commands, in the order of commands.COMMANDS, as ``--help`` lists them.
COMMAND_MODULES: tuple[str, ...] = tuple(dict.fromkeys(f"finaldrive.service.cli.{c.module}" for c in COMMANDS.values()))

__all__ = ["UsageError", "build_parser", "main"]


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # argparse's hook: one line, exit code 2 (main)
        raise UsageError(message)


def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("finaldrive")
    except PackageNotFoundError:  # running from a tree that was never installed
        return "unknown"


class _Version(argparse.Action):
    """--version, read from the package's metadata only when asked for."""

    def __call__(self, parser: argparse.ArgumentParser, *_: Any) -> NoReturn:
        print(f"finaldrive {package_version()}")
        parser.exit()


def build_parser(command: str | None = None, *, every: bool = False) -> argparse.ArgumentParser:
    """The parser for ``command``: its module's commands in full, the others as their names and help only
    (commands.COMMANDS), so that a command, ``--help`` and ``--version`` import one module or none;
    ``every``: every command in full."""
    doc = __doc__ or ""
    parser = _Parser(prog="finaldrive", description=doc.splitlines()[0], **parser_options())
    parser.add_argument("--version", action=_Version, nargs=0, help="print the version and exit")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser, metavar="COMMAND")
    wanted = COMMANDS[command].module if command in COMMANDS else None
    for module in COMMAND_MODULES:
        name = module.rsplit(".", 1)[1]
        if every or name == wanted:
            importlib.import_module(module).register(sub)
        else:
            for listed, spec in COMMANDS.items():
                if spec.module == name:
                    sub.add_parser(listed, help=spec.help, add_help=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    words = sys.argv[1:] if argv is None else argv
    parser = build_parser(next((w for w in words if not w.startswith("-")), None))
    try:
        args = parser.parse_args(argv)
        return int(args.run(args) or 0)
    except UsageError as exc:
        print(f"finaldrive: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("finaldrive: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (e.g. `finaldrive roads | head`): stop quietly, as `cat` does
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except OSError as exc:  # a file that could not be read or written after the arguments were checked
        where = f" {exc.filename!r}" if exc.filename else ""
        print(f"finaldrive: error:{where} {exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
