"""Every `remarl-fc` command and every ``tools/*.py`` command the README and the docs show
exists as shown.

The docs write commands as a user types them and as synopses (``[--json]``, ``off|on``,
placeholders such as ``FILE`` or ``N``), so they are not parsed whole: for each one, its
command words must name a command of `build_parser` (or the tool's file must exist), every
``--option`` must be an option of that command or tool (spelled in full: argparse would accept
an abbreviation the docs should not teach), and every literal value given to an option with
choices must be one of them. A tool's parser is the one its ``main()`` builds, taken from it
at its ``parse_args`` call, before it runs anything.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import sys
from pathlib import Path
from typing import Any, NoReturn

import pytest

from remarl_fc.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

FENCE = re.compile(r"```[^\n]*\n(.*?)```", re.S)
INLINE = re.compile(r"`([^`]+)`")
COMMAND = re.compile(r"(?:^|[\s(]|bin/)remarl-fc\s+([a-z][^\n]*)")
TOOL = re.compile(r"(?:^|[\s(])(tools/[a-z_]+\.py)\b([^\n]*)")
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


def _matches(pattern: re.Pattern[str]) -> list[tuple[str, re.Match[str]]]:
    """(file, match) for each match of ``pattern`` in the code of the docs."""
    return [
        (path.name, match)
        for path in DOCS
        for snippet in _snippets(path.read_text(encoding="utf-8"))
        for match in pattern.finditer(snippet)
    ]


def _cut(text: str) -> str:
    """``text`` up to where its command ends (`END`)."""
    return END.split(text, maxsplit=1)[0].strip()


def _commands() -> list[tuple[str, str]]:
    """(file, command after ``remarl-fc``) for every command in the docs."""
    return [(name, _cut(match.group(1))) for name, match in _matches(COMMAND)]


def _tool_commands() -> list[tuple[str, str, str]]:
    """(file, ``tools/NAME.py``, its arguments as shown) for every tool the docs name."""
    return [(name, match.group(1), _cut(match.group(2))) for name, match in _matches(TOOL)]


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
            problems.append(f"no option {name} in `{parser.prog}`")
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


class _Parsed(Exception):
    """Raised in place of a tool's ``parse_args``: it carries the parser, and stops the tool."""

    def __init__(self, parser: argparse.ArgumentParser) -> None:
        super().__init__(parser.prog)
        self.parser = parser


def _stop(self: argparse.ArgumentParser, *args: Any, **kwargs: Any) -> NoReturn:
    raise _Parsed(self)


def _tool_parser(tool: str, monkeypatch: pytest.MonkeyPatch) -> argparse.ArgumentParser | None:
    """The parser ``tool``'s ``main()`` builds, or None where it takes no options."""
    if "ArgumentParser" not in (ROOT / tool).read_text(encoding="utf-8"):
        return None
    spec = importlib.util.spec_from_file_location(f"docs_{Path(tool).stem}", ROOT / tool)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    imported = set(sys.modules)
    with monkeypatch.context() as patch:
        patch.syspath_prepend(str(ROOT / "tools"))  # a tool imports its siblings, as when run
        patch.setattr(argparse.ArgumentParser, "parse_args", _stop)
        patch.setattr(argparse.ArgumentParser, "parse_known_args", _stop)
        try:
            spec.loader.exec_module(module)
            module.main()
        except _Parsed as parsed:
            parsed.parser.prog = Path(tool).name  # not the test runner's argv[0]
            return parsed.parser
        finally:
            for sibling in set(sys.modules) - imported:
                if (getattr(sys.modules[sibling], "__file__", None) or "").startswith(
                    str(ROOT / "tools")
                ):
                    del sys.modules[sibling]
    return None


COMMANDS = _commands()
TOOL_COMMANDS = _tool_commands()


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


def test_every_tool_command_in_the_docs_exists_as_shown(monkeypatch):
    """``python tools/NAME.py --option …``: the file is there, and its parser has the options."""
    tools = sorted({tool for _, tool, _ in TOOL_COMMANDS})
    assert len(tools) > 20 and sum("--" in rest for *_, rest in TOOL_COMMANDS) > 50
    missing = sorted(
        {f"{name}: {tool}" for name, tool, _ in TOOL_COMMANDS if not (ROOT / tool).is_file()}
    )
    assert not missing, "\n".join(missing)
    parsers = {tool: _tool_parser(tool, monkeypatch) for tool in tools}
    wrong = []
    for name, tool, rest in TOOL_COMMANDS:
        parser = parsers[tool]
        if parser is None:
            wrong += [f"{name}: {tool} {rest}: {tool} takes no options"] if "--" in rest else []
        else:
            wrong += [f"{name}: {tool} {rest}: {p}" for p in _problems(rest, parser)]
    assert not wrong, "\n".join(wrong)


def test_a_tools_parser_is_taken_before_it_runs(monkeypatch):
    """The parser of a tool is its own (its options), and taking it runs nothing."""
    parser = _tool_parser("tools/uav_collisions.py", monkeypatch)
    assert parser is not None and "--shield" in parser._option_string_actions
    assert _problems("--real-world --shieldd", parser) == [
        "no option --shieldd in `uav_collisions.py`"
    ]
    assert _tool_parser("tools/zoo_table.py", monkeypatch) is None  # no options, not run
