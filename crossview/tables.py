"""What a command prints, in the format the user asks for: one rule for every command that prints a table.

`--format text|json|markdown` chooses what goes to stdout (default text, the terminal's table); `-o FILE` (or the
command's own figures option) also writes it to FILE, in `--format` when given, else in the format its suffix
names (.json, .md), else text, atomically (`crossview.outputs`), and says where. After JSON or Markdown on stdout
that line goes to stderr, so that stdout stays one document (`crossview score ... --format json | jq .mota`).

A command hands over three things: its figures (a JSON-ready dict: the json format), its text (the terminal
table as it has always printed) and its blocks for Markdown: lines of words and `Table`s. A command without
tables of its own gives none, and its figures become a two-column table of dotted key and value (`key_values`).
"""

from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from pathlib import Path

FORMATS = ("text", "json", "markdown")
FORMAT_NAMES = {"text": "text", "json": "JSON", "markdown": "Markdown"}
_SUFFIX_FORMATS = {".json": "json", ".md": "markdown", ".markdown": "markdown"}


@dataclass(frozen=True)
class Table:
    """A table of cells already formatted as text: a header row and rows of the same width."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]

    def __post_init__(self):
        bad = next((r for r in self.rows if len(r) != len(self.header)), None)
        if bad is not None:
            raise ValueError(f"row {bad!r} has {len(bad)} cells; the header has {len(self.header)}")

    def text(self) -> str:
        """Aligned columns: the first left, the others right, a rule under the header."""
        widths = [max(len(c) for c in col) for col in zip(self.header, *self.rows)]

        def line(cells):
            return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))

        return "\n".join([line(self.header), "-" * len(line(self.header)), *(line(r) for r in self.rows)])

    def markdown(self) -> str:
        def line(cells):
            return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

        return "\n".join([line(self.header), "|" + "---|" * len(self.header), *(line(r) for r in self.rows)])


def _value(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return "-" if not math.isfinite(v) else f"{v:.6g}"
    return str(v)


def key_values(figures: dict, header: tuple[str, str] = ("figure", "value")) -> Table:
    """Every figure of a (nested) dict as a row of its dotted key and its value; lists of numbers in one cell."""
    rows = []

    def walk(prefix, value):
        if isinstance(value, dict):
            for k, v in value.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        elif isinstance(value, (list, tuple)) and any(isinstance(v, (dict, list, tuple)) for v in value):
            for i, v in enumerate(value):
                walk(f"{prefix}[{i}]", v)
        elif isinstance(value, (list, tuple)):
            rows.append((prefix, ", ".join(_value(v) for v in value)))
        else:
            rows.append((prefix, _value(value)))

    walk("", figures)
    return Table(header, tuple(rows))


def markdown(blocks) -> str:
    """Markdown of lines of words (each its own paragraph) and `Table`s."""
    return "\n\n".join(b.markdown() if isinstance(b, Table) else str(b) for b in blocks) + "\n"


def render(fmt: str, figures: dict, text: str | None = None, blocks=None) -> str:
    """The command's output in `fmt`, ending in a newline: the figures as JSON (NaN and infinities as null), the
    Markdown `blocks` or the `text`, each by default the figures' key-value table (`key_values`)."""
    if fmt == "json":
        return json.dumps(_finite(figures), indent=2, allow_nan=False, default=_json_default) + "\n"
    if fmt == "markdown":
        return markdown(blocks if blocks is not None else [key_values(figures)])
    if fmt == "text":
        return (text if text is not None else key_values(figures).text()).rstrip("\n") + "\n"
    raise ValueError(f"format {fmt!r}: one of {', '.join(FORMATS)}")


def _finite(value):
    """`value` with every NaN or infinite float as None (JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


def _json_default(value):
    raise TypeError(f"{type(value).__name__} is not JSON data")


def file_format(path: Path, fmt: str | None) -> str:
    """The format of a written file: `--format` when given, else its suffix's (.json, .md), else text."""
    return fmt or _SUFFIX_FORMATS.get(Path(path).suffix.lower(), "text")


def emit(figures: dict, *, fmt: str | None, output: Path | None = None, what: str = "figures", text: str | None = None,
         blocks=None, inputs: tuple = (), extra_text: str | None = None) -> None:
    """Prints the command's output in `fmt` (None: text) and, with `output`, writes it there too (in
    `file_format`), then says where: `WHAT FORMAT: PATH` (on stderr after JSON or Markdown on stdout).

    Args:
        figures: the JSON-ready figures (NaN and infinities as None).
        fmt: the `--format` given, or None.
        output: the file to write, or None.
        what: what the file holds, for the line saying where ("score" gives "score JSON: PATH").
        text: the terminal table (default: the figures' key-value table).
        blocks: the Markdown blocks (default: the figures' key-value table).
        inputs: the command's inputs, which `output` must not be.
        extra_text: lines printed after a text table only (notes for the terminal, not part of the figures).
    """
    from crossview import outputs

    shown = fmt or "text"
    sys.stdout.write(render(shown, figures, text, blocks))
    if shown == "text" and extra_text:
        sys.stdout.write(extra_text.rstrip("\n") + "\n")
    if output is not None:
        written = file_format(output, fmt)
        outputs.write_bytes(render(written, figures, text, blocks).encode("utf-8"), output, inputs)
        print(f"{what} {FORMAT_NAMES[written]}: {output}", file=sys.stdout if shown == "text" else sys.stderr)
