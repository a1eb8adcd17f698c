"""The docs and the command line agree: every `crossview COMMAND --flag` written in README.md and docs/*.md names a
command the parser has and flags that command takes (its own or the global ones, shown in --help), and every flag
written alone in backticks is one some command takes. Generic: a command added later is covered as it is."""

from __future__ import annotations

import argparse
import re
import shlex
from pathlib import Path

import pytest

from crossview.cli import build_parser

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)
_SPAN = re.compile(r"(?<!`)`([^`\n]+)`(?!`)")
_END = {"|", ";", "&&", "||", ">", "2>", "#", "&"}


def visible_options(parser: argparse.ArgumentParser) -> set[str]:
    """The option strings --help shows (the hidden old spellings left out), read from --help itself."""
    flags = set()
    for line in parser.format_help().splitlines():
        if re.match(r"\s{2}-", line):  # "  -o PATH, --output PATH  what it is"
            invocation = re.split(r"\s{2,}", line.strip())[0]
            flags.update(re.findall(r"(?:^|, )(--?[A-Za-z][\w-]*)", invocation))
    return flags


def every_spelling() -> set[str]:
    """Every option spelling the command line's source defines, the hidden old ones (--out, --minutes) included."""
    return set(re.findall(r"[\"'](--?[a-z][\w-]*)[\"']", (ROOT / "crossview" / "cli.py").read_text(encoding="utf-8")))


def _code(text: str, spans_only: bool = False) -> list[tuple[str, str]]:
    """(line, code) of each line of a fenced block and each backtick span, with the line it is on."""
    out = []
    if not spans_only:
        for block in _FENCE.findall(text):
            out += [(line, line.strip().removeprefix("$ ")) for line in block.splitlines()]
    for line in _FENCE.sub("", text).splitlines():
        out += [(line, span) for span in _SPAN.findall(line)]
    return out


def invocations(text: str) -> list[tuple[str, list[str]]]:
    """(line, the tokens after `crossview`) of each command written in code: a fenced block's line or a backtick
    span that starts with `crossview `, up to a pipe, a redirection or a comment."""
    found = []
    for line, code in _code(text):
        if not code.startswith("crossview "):
            continue
        try:
            tokens = shlex.split(code.removeprefix("crossview "), comments=True)
        except ValueError:  # (an unclosed quote: a span cut short)
            tokens = code.removeprefix("crossview ").split()
        cut = next((i for i, t in enumerate(tokens) if t in _END), len(tokens))
        found.append((line, [t.strip("[]{}") for t in tokens[:cut]]))  # (`[--seed N]`: an optional flag)
    return found


def lone_flags(text: str) -> list[tuple[str, str]]:
    """(line, flag) of each flag written alone in a backtick span (`--speed`, `--cameras N`), outside code blocks."""
    return [(line, code.split()[0].partition("=")[0]) for line, code in _code(text, spans_only=True)
            if re.fullmatch(r"--[a-z][a-z0-9-]*(?:[ =][^`]*)?", code)]


def problems(text: str, parser) -> list[str]:
    """What a page's text names that the parser does not have. An old spelling the parser still accepts but hides
    from --help may be named only on a line that says it is old (`--out`, the older spelling of -o)."""
    commands = parser.commands
    top = visible_options(parser)
    every = top.union(*(visible_options(p) for p in commands.values()))
    hidden = every_spelling() - every

    def fine(flag: str, valid: set[str], line: str) -> bool:
        return flag in valid or (flag in hidden and re.search(r"\bold(er)?\b", line) is not None)

    found = []
    for line, tokens in invocations(text):
        words = [t for t in tokens if not t.startswith("-")]
        flags = [t.partition("=")[0] for t in tokens if t.startswith("-") and len(t) > 1 and not t[1].isdigit()]
        name = words[0] if words else None  # (none: `crossview --version`)
        if name is not None and not re.fullmatch(r"[a-z][a-z-]*", name):  # (a placeholder: `crossview COMMAND`)
            continue
        if name is not None and name not in commands:
            found.append(f"crossview {name}: no such command")
            continue
        valid = top | (visible_options(commands[name]) if name else set())
        found += [f"crossview {name or ''} {flag}: no such flag".replace("  ", " ") for flag in flags
                  if not fine(flag, valid, line)]
    found += [f"{flag}: no command takes it" for line, flag in lone_flags(text) if not fine(flag, every, line)]
    return sorted(set(found))


BAD_INPUT_TABLE = ROOT / "docs" / "reliability.md"
"""Its table's rows name bad input on purpose (`crossview --bogus`): they are left out; the rest of the page is not."""


@pytest.mark.parametrize("doc", DOCS, ids=[d.name for d in DOCS])
def test_every_command_and_flag_the_docs_name_exists(doc):
    text = doc.read_text(encoding="utf-8")
    if doc == BAD_INPUT_TABLE:
        text = "\n".join(line for line in text.splitlines() if not line.startswith("| "))
    assert problems(text, build_parser()) == []


def test_the_check_finds_what_does_not_exist():
    parser = build_parser()
    assert problems("Run `crossview world-stats store_layout1 --minutes 5`.", parser) == [
        "crossview world-stats --minutes: no such flag"]
    assert problems("```\ncrossview bogus -o x\n```\n", parser) == ["crossview bogus: no such command"]
    assert problems("Give `--jsonx PATH`.", parser) == ["--jsonx: no command takes it"]
    assert problems("```\ncrossview run --duration 5 | head -1  # --nothing\n```\n`--speed`", parser) == []

