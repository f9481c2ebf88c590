"""The commands and examples the documentation shows still work: every ``follow-*`` command
line in a page's code blocks is accepted by its command's argument parser, every ``python -m``
module and ``make`` target it names exists, and every Python example in the README runs. So a
renamed option, a removed module or an example that no longer runs shows here, not to a user
copying it.

The command lines are parsed, not run (most train agents or run thousands of episodes); the
checks that need their files (a run folder, a model) are the commands' own tests'.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import shlex
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from bridge.cli import _parser as robot_parser
from eval.cli import build_parser as eval_parser
from eval.tuning.cli import build_parser as tune_parser
from tests.test_doc_links import PAGES, ROOT
from train.cli import build_parser as train_parser

PARSERS: dict[str, Callable[[], argparse.ArgumentParser]] = {
    "follow-eval": eval_parser,
    "follow-robot": robot_parser,
    "follow-train": train_parser,
    "follow-tune": tune_parser,
}
BLOCK = re.compile(r"```(\w*)\n(.*?)```", re.S)
# A command at the start of a line; "follow-robot: ..." is a command's output, not a command.
COMMAND = re.compile(r"^(follow-(?:eval|robot|train|tune)|python -m|make)\s")
# Placeholders the pages write for what the user fills in, and what stands for them here.
PLACEHOLDERS = {
    "<timestamp>": "20261201-120000",
    "<time>": "20261201-120000",
    "<all 12>": "straight,curve",
}


def _shell(word: str) -> str:
    """A word as the shell would give it, near enough for a parser: a brace expansion
    (``runs/d-{1,2}``) as its first alternative, a shell variable (a loop's ``$1``) as 1, which
    every option that takes one in the pages accepts (a seed, a count, part of a name)."""
    word = re.sub(r"\{([^{},]*),[^{}]*\}", r"\1", word)
    return re.sub(r"\$(\w+|\{\w+\})", "1", word)


def commands(page: Path) -> list[tuple[int, list[str]]]:
    """The command lines of ``page``'s shell code blocks (comments, continuation lines and
    ``for`` loops' bodies included), each with its line number and its words."""
    found = []
    text = page.read_text()
    for match in BLOCK.finditer(text):
        if match.group(1) not in ("bash", "sh", "console", ""):
            continue
        first = text.count("\n", 0, match.start(2)) + 1
        lines = match.group(2).split("\n")
        joined: list[tuple[int, str]] = []
        for i, line in enumerate(lines):
            if joined and joined[-1][1].endswith("\\"):
                joined[-1] = (joined[-1][0], joined[-1][1][:-1] + " " + line.strip())
            else:
                joined.append((first + i, line.strip()))
        for number, line in joined:
            line = line.removeprefix("$ ")
            if not COMMAND.match(line):
                continue
            for placeholder, value in PLACEHOLDERS.items():
                line = line.replace(placeholder, value)
            words = [_shell(w) for w in shlex.split(line, comments=True)]
            found.append((number, words))
    return found


ALL = [(page, number, words) for page in PAGES for number, words in commands(page)]


def test_the_pages_have_commands_to_check() -> None:
    """The checks below are not vacuous: the README's commands are found, each kind of them."""
    readme = [words for page, _, words in ALL if page == ROOT / "README.md"]
    assert len(readme) >= 40
    kinds = {words[0] if words[0] != "python" else "python -m" for words in readme}
    assert kinds == {*PARSERS, "python -m", "make"}
    # a continued line is one command, with its options from every line; a brace expansion
    # is one of its words
    first = ["follow-eval", "dominance", "runs/dominance-30000", "--learner"]
    assert any(w[:4] == first and "--laws" in w for w in readme)


def test_a_wrong_option_is_caught() -> None:
    """The check fails on what it is meant to catch."""
    with pytest.raises(ValueError, match="--polices"):
        _parse(["follow-eval", "run", "--polices", "pn"])
    with pytest.raises(ValueError, match="dqn"):
        _parse(["follow-train", "--algo", "dqn"])
    with pytest.raises(ValueError, match="--episodes"):
        _parse(["follow-eval", "run", "--episodes", "$2"])
    assert _shell("runs/d-{30000,50000}") == "runs/d-30000"
    assert _shell("runs/d-$1") == "runs/d-1"


def _parse(words: list[str]) -> None:
    """Parse ``words`` with their command's parser; an error in the line raises ValueError
    with the parser's message (the commands' parsers raise their own errors, or exit 2)."""
    parser = PARSERS[words[0]]()
    try:
        parser.parse_args(words[1:])
    except SystemExit as exc:
        raise ValueError(f"{shlex.join(words)}: exit {exc.code}") from None
    except Exception as exc:  # each command's UsageError
        raise ValueError(f"{shlex.join(words)}: {exc}") from None


@pytest.mark.parametrize(
    ("page", "number", "words"), ALL, ids=[f"{p.relative_to(ROOT)}:{n}" for p, n, _ in ALL]
)
def test_every_documented_command_is_accepted(
    page: Path, number: int, words: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    where = f"{page.relative_to(ROOT)}, line {number}: {shlex.join(words)}"
    if words[0] == "make":
        targets = re.findall(r"^([\w.-]+):", (ROOT / "Makefile").read_text(), re.M)
        assert words[1] in targets, f"{where}: no such make target"
    elif words[0] == "python":
        assert words[1] == "-m", where
        assert importlib.util.find_spec(words[2]) is not None, f"{where}: no such module"
    else:
        try:
            _parse(words)
        except ValueError as exc:
            pytest.fail(f"{where}: {exc} {capsys.readouterr().err.strip()}")


def _python_examples() -> list[tuple[int, str]]:
    text = (ROOT / "README.md").read_text()
    return [
        (text.count("\n", 0, m.start(2)) + 1, m.group(2))
        for m in BLOCK.finditer(text)
        if m.group(1) == "python"
    ]


def test_the_readmes_python_examples_run(tmp_path: Path) -> None:
    """In order, in one fresh interpreter, as a reader pasting them into one session would (one
    registers a scenario of its own, which must not leak into the other tests); the serial
    example talks to pyserial's loopback port instead of a robot's."""
    examples = _python_examples()
    assert len(examples) >= 8
    script = tmp_path / "examples" / "readme_examples.py"
    script.parent.mkdir()
    code = "\n".join(
        f"# README.md, the example at line {number}\n" + code.replace('"/dev/ttyUSB0"', '"loop://"')
        for number, code in examples
    )
    script.write_text(code, encoding="utf-8")
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    done = subprocess.run(
        [sys.executable, str(script)], cwd=cwd, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert list(cwd.iterdir()) == [], "an example left files behind"
