"""Every `remarl-fc` command that the README and the docs show exists as shown.

The docs write commands as a user types them and as synopses (``[--json]``, ``off|on``,
placeholders such as ``FILE`` or ``N``), so they are not parsed whole: for each one, its
command words must name a command of `build_parser`, every ``--option`` must be an option of
that command (spelled in full: argparse would accept an abbreviation the docs should not
teach), and every literal value given to an option with choices must be one of them.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from remarl_fc.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

FENCE = re.compile(r"```[^\n]*\n(.*?)```", re.S)
INLINE = re.compile(r"`([^`]+)`")
COMMAND = re.compile(r"(?:^|[\s(]|bin/)remarl-fc\s+([a-z][^\n]*)")
END = re.compile(r"\s#|\s{3,}|&&|;|\|\s*(?:head|tail|grep|jq|tee|less)\b")
"""Where a command stops: a shell comment, a synopsis' description column, the next command,
or a pipe into another program (a ``|`` in a synopsis separates alternatives: all are checked)."""
OPTION = re.compile(r"^[\[(]*(--[a-z][a-z0-9-]*)")
PLACEHOLDER = re.compile(r"[A-Z]|\.\.\.|…")
"""A value the reader fills in (``FILE``, ``N``, ``HOST:PORT``) or leaves out."""


def _snippets(text: str) -> list[str]:
    """The code of ``text``: each line of its fenced blocks (continuations joined), and each
    inline code span (a span may wrap over lines)."""
    out = [
        line for block in FENCE.findall(text) for line in block.replace("\\\n", " ").splitlines()
    ]
    prose = FENCE.sub("", text)
    out += [span.replace("\n", " ") for span in INLINE.findall(prose)]
    return out


def _commands() -> list[tuple[str, str]]:
    """(file, command after ``remarl-fc``) for every command in the docs."""
    found = []
    for path in DOCS:
        for snippet in _snippets(path.read_text(encoding="utf-8")):
            for match in COMMAND.finditer(snippet):
                command = END.split(match.group(1), maxsplit=1)[0].strip()
                found.append((path.name, command))
    return found


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _problems(command: str, root: argparse.ArgumentParser) -> list[str]:
    """What in ``command`` (without ``remarl-fc``) the parser does not have."""
    words = command.split()
    parser, i = root, 0
    while i < len(words) and (choices := _subcommands(parser)):
        word = words[i].strip("[]()")
        if word.startswith("-") or PLACEHOLDER.search(word):
            break
        if word not in choices:
            return [f"no command {word!r} (commands: {', '.join(choices)})"]
        parser, i = choices[word], i + 1
    known = parser._option_string_actions
    problems = []
    for j in range(i, len(words)):
        option = OPTION.match(words[j])
        if option is None:
            continue
        name = option.group(1)
        action = known.get(name)
        if action is None:
            problems.append(f"no option {name} in `remarl-fc {parser.prog.split(' ', 1)[-1]}`")
            continue
        if action.choices is None or j + 1 >= len(words) or "=" in words[j]:
            continue
        value = words[j + 1].strip("[]()")
        if value.startswith("-") or PLACEHOLDER.search(value):
            continue
        for alternative in value.split("|"):
            if alternative and alternative not in action.choices:
                problems.append(f"{name} {alternative!r} is not one of {list(action.choices)}")
    return problems


COMMANDS = _commands()


def test_the_docs_show_commands():
    """The extraction finds the README's synopsis and the docs' commands (it cannot pass empty)."""
    files = {name for name, _ in COMMANDS}
    assert {"README.md", "FLYING.md", "MODEL.md", "RESULTS.md"} <= files
    assert len(COMMANDS) > 100


@pytest.mark.parametrize(
    "command",
    [
        "eval --suite standard --policy generalist --shield-horizon S",
        "train --generalist [--minutes 60] [--device auto|cpu|cuda]",
        "bench sitl --vehicles 100 [--json]",
    ],
)
def test_a_good_command_has_no_problems(command):
    assert _problems(command, build_parser()) == []


@pytest.mark.parametrize(
    ("command", "problem"),
    [
        ("eval --suite standard --shield-horizn 4", "no option --shield-horizn"),
        ("eval --shield off|sometimes", "'sometimes' is not one of"),
        ("evaluate --policy generalist", "no command 'evaluate'"),
        ("bench bogus --json", "no command 'bogus'"),
        ("train --gen", "no option --gen"),  # an abbreviation argparse would take
    ],
)
def test_a_wrong_command_is_found(command, problem):
    problems = _problems(command, build_parser())
    assert len(problems) == 1 and problem in problems[0], problems


def test_every_command_in_the_docs_exists_as_shown():
    parser = build_parser()
    wrong = [
        f"{name}: remarl-fc {command}: {problem}"
        for name, command in COMMANDS
        for problem in _problems(command, parser)
    ]
    assert not wrong, "\n".join(wrong)


def test_every_tool_the_docs_name_exists():
    """``python tools/NAME.py`` and the like: the file is there."""
    named = {
        (path.name, tool)
        for path in DOCS
        for tool in re.findall(r"\btools/[a-z_]+\.py\b", path.read_text(encoding="utf-8"))
    }
    assert len(named) > 20
    missing = [f"{name}: {tool}" for name, tool in sorted(named) if not (ROOT / tool).is_file()]
    assert not missing, "\n".join(missing)
