"""finaldrive: motorcycle final-drive geometry by multibody simulation on uneven roads.

The command line.
Each command group lives in its own module exposing ``register(subparsers)``; ``main`` wires
them together. Bad arguments exit with code 2 and one line on stderr.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

#: Modules that add commands, in the order their commands appear in ``--help``.
COMMAND_MODULES: tuple[str, ...] = ("service.cli.engine_cmds", "service.cli.server_cmds", "service.cli.study_paper_cmds",
                                   "service.cli.study_cmds", "service.cli.client_cmds")


class UsageError(Exception):
    """A bad argument: reported on one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # noqa: D102 - argparse hook
        raise UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="finaldrive", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
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


if __name__ == "__main__":
    sys.exit(main())
