"""Generate the docs' example outputs: run each example command again and write what it printed.

    python bench/docs_examples.py            # run every example of README.md and docs/, rewrite its block
    python bench/docs_examples.py --check    # run them, list the blocks that differ (times, ports aside), exit 1 if any

An example is a code block right after a marker ``<!-- example: COMMAND -->``; the block is
``$ COMMAND`` and then what the command printed (stdout and stderr, as a terminal shows them). Each
command runs with ``bash -c`` in a fresh temporary folder, so the demo makes its own database and
log there. ``<!-- example cold: COMMAND -->`` also gives it a fresh compile cache (``NUMBA_CACHE_DIR``):
the first run on a machine, compilation included; its output depends on the machine's speed and
load, so ``tests/test_docs_examples.py`` compares only the other examples (timings masked).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: The marker, its code block (no language) and what follows it.
_EXAMPLE = re.compile(r"<!-- example( cold)?: (?P<command>[^\n]+?) -->\n```\n(?P<block>.*?)```\n", re.S)
#: Times, free ports and the executor a machine's core count picks: what differs between two runs.
_VOLATILE = (
    (re.compile(r"\b\d+(\.\d+)? s\b"), "<t> s"),
    (re.compile(r"127\.0\.0\.1:\d+"), "127.0.0.1:<port>"),
    (re.compile(r"executor (serial|process|ray)\b"), "executor <kind>"),
)
#: Longest an example may run [s].
TIMEOUT_S = 900.0


@dataclass(frozen=True)
class Example:
    """One example: where its block is, its command, whether it runs cold, the block as written."""

    path: Path
    command: str
    cold: bool
    block: str
    start: int
    end: int


def documents() -> list[Path]:
    """The README and every page of docs/."""
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def examples(path: Path) -> list[Example]:
    """The examples of one document, in order."""
    text = path.read_text()
    return [Example(path, m["command"], bool(m[1]), m["block"], m.start("block"), m.end("block"))
            for m in _EXAMPLE.finditer(text)]


def run(example: Example) -> str:
    """Run the example's command in a fresh folder; the block it makes (``$ COMMAND``, then the output)."""
    with tempfile.TemporaryDirectory(prefix="finaldrive-example-") as folder:
        env = dict(os.environ)
        if example.cold:
            env["NUMBA_CACHE_DIR"] = str(Path(folder) / "numba-cache")
        done = subprocess.run(["bash", "-c", example.command], cwd=folder, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, timeout=TIMEOUT_S, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"{example.path.name}: `{example.command}` exited {done.returncode}:\n{done.stdout}")
    return f"$ {example.command}\n{done.stdout.rstrip()}\n"


def masked(block: str) -> str:
    """The block with its times and ports replaced, for comparing two runs."""
    for pattern, replacement in _VOLATILE:
        block = pattern.sub(replacement, block)
    return block


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="compare, do not write")
    args = parser.parse_args(argv)
    stale = 0
    for path in documents():
        found = examples(path)
        if not found:
            continue
        text = path.read_text()
        for example in reversed(found):   # from the end, so earlier offsets hold
            block = run(example)
            if args.check:
                if masked(block) != masked(example.block):
                    stale += 1
                    print(f"{path.relative_to(REPO)}: `{example.command}` prints otherwise now", file=sys.stderr)
            else:
                text = text[:example.start] + block + text[example.end:]
                print(f"{path.relative_to(REPO)}: `{example.command}`", file=sys.stderr)
        if not args.check:
            path.write_text(text)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
