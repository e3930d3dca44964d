"""Every `graspkit ...` command line quoted in README.md, docs/*.md and the lessons names a command that exists and
only options that command has (the quotes are often partial: required options may be left out, values may be
placeholders, so the command path and the option names are checked, not a full parse)."""
import argparse
import re
from pathlib import Path

import pytest

from graspkit.cli import build_parser

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
           *sorted((ROOT / "notebooks" / "src").glob("*.py"))]


def quoted_commands(path: Path) -> list[str]:
    """The `graspkit <command> ...` spans of a file (inline code, or lines of a fenced block), comments cut."""
    text = path.read_text()
    spans = re.findall(r"`(graspkit [a-z][^`]*)`", text)
    for block in re.findall(r"```[a-z]*\n(.*?)```", text, re.S):
        spans += [line.strip() for line in block.splitlines() if line.strip().startswith("graspkit ")]
    # a span may wrap across a lesson's comment lines ("# ..."): join them
    return [re.sub(r"\s*\n\s*#?\s*", " ", s).split(" # ")[0] for s in spans]


def subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """A parser's subcommands by name ({} when it has none)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def resolve(tokens: list[str]) -> tuple[argparse.ArgumentParser, list[str], list[str]]:
    """The parser of the command the tokens name (after 'graspkit'), the command path and the remaining tokens."""
    parser, path, rest = build_parser(tokens), [], list(tokens)
    while rest and subparsers(parser) and not rest[0].startswith("-"):
        subs = subparsers(parser)
        if rest[0] not in subs:
            break
        parser, path = subs[rest[0]], path + [rest.pop(0)]
    return parser, path, rest


COMMANDS = [(p, c) for p in SOURCES for c in quoted_commands(p)]


def test_the_docs_quote_commands():
    assert len(COMMANDS) >= 50 and {p.name for p, _ in COMMANDS} >= {"README.md", "wandr.md", "saga.md"}


@pytest.mark.parametrize("path,command", COMMANDS, ids=[f"{p.name}:{c[:40]}" for p, c in COMMANDS])
def test_a_quoted_command_exists_with_its_options(path, command):
    tokens = command.split()[1:]
    parser, names, rest = resolve(tokens)
    assert names, f"{path.name}: `{command}` names no graspkit command"
    if subparsers(parser):                              # `graspkit eval` alone is a command (--all); `train` is not
        placeholder = rest and (rest[0] in ("...", "…") or rest[0].isupper())    # `graspkit train ...`, `MODEL`
        assert names[0] == "eval" or placeholder or not rest or rest[0].startswith("-"), (
            f"{path.name}: `{command}`: no subcommand {rest[0] if rest else ''!r} of `graspkit {' '.join(names)}`")
    options = {o for a in parser._actions for o in a.option_strings}
    for tok in rest:
        flag = tok.strip("[](){},.;:").split("=")[0]
        if flag.startswith("--") and len(flag) > 2:
            assert flag in options, f"{path.name}: `{command}`: `graspkit {' '.join(names)}` has no option {flag}"
