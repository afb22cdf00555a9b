"""The docs' example outputs are generated (bench/docs_examples.py), and still what the commands print."""

from __future__ import annotations

import re

import pytest

from bench.docs_examples import Example, documents, examples, masked, run

ALL = [example for path in documents() for example in examples(path)]
#: A code block that shows a command's output: its first line is a prompt and a finaldrive command.
_OUTPUT_BLOCK = re.compile(r"```\n\$ finaldrive")


def test_the_docs_have_generated_examples() -> None:
    commands = {example.command.split(" --")[0] for example in ALL}
    assert {"finaldrive demo", "finaldrive optimize", "finaldrive geometry"} <= commands


@pytest.mark.parametrize("example", ALL, ids=lambda e: f"{e.path.name}:{e.command[:40]}")
def test_an_example_block_is_its_command_and_what_it_printed(example: Example) -> None:
    lines = example.block.splitlines()
    assert lines[0] == f"$ {example.command}", "run python bench/docs_examples.py"
    assert len(lines) > 1, f"`{example.command}` has no output in {example.path.name}: run bench/docs_examples.py"


def test_no_output_block_is_typed() -> None:
    """Every block that shows a finaldrive command's output follows an example marker."""
    for path in documents():
        text = path.read_text()
        marked = {e.start for e in examples(path)}
        for m in _OUTPUT_BLOCK.finditer(text):
            assert m.start() + 4 in marked, f"{path.name}: a typed output block at offset {m.start()}"


def test_masking_hides_times_ports_and_the_executor_only() -> None:
    assert masked("service up after 20 s at http://127.0.0.1:45839, 84 simulations, 1.6 s") == (
        "service up after <t> s at http://127.0.0.1:<port>, 84 simulations, <t> s")
    assert masked("6 generations, stop: max_iter, executor process, 2.6 s") == (
        "6 generations, stop: max_iter, executor <kind>, <t> s")
    assert masked("a2 = 344.1 deg") == "a2 = 344.1 deg"


@pytest.mark.slow
@pytest.mark.parametrize("example", [e for e in ALL if not e.cold], ids=lambda e: f"{e.path.name}:{e.command[:40]}")
def test_an_example_prints_what_the_docs_show(example: Example) -> None:
    """Run again, the example prints its block, times aside (the cold ones depend on the machine's load)."""
    assert masked(run(example)) == masked(example.block), "stale: run python bench/docs_examples.py"
