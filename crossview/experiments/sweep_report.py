"""A sweep's report: means and spreads over seeds, breaking points, report.md and its matplotlib plots."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

from crossview import outputs, pipeline

PCP_LIMIT = 0.95
"""A line breaks at the first value where the mean PCP over seeds falls below this."""
IDF1_LIMIT = 0.90
"""... or where the mean IDF1 over seeds falls below this."""

METRICS = (
    ("pcp", "PCP", PCP_LIMIT),
    ("idf1", "IDF1", IDF1_LIMIT),
    ("mota", "MOTA", None),
    ("id_switches", "ID switches", None),
    ("false_positives", "false positives", None),
    ("tracker_fps", "tracker FPS (all cameras once)", None),
)
"""(score JSON field, title, limit drawn on its plot) of each plot."""


@dataclass(frozen=True)
class Point:
    """One metric over the seeds of one x value of one line: mean, min and max of the cells that ran
    (NaN where none did), how many ran of how many, and the first failed cell's error."""

    mean: float
    low: float
    high: float
    ok: int
    cells: int
    error: str | None


def _lines(wanted: dict, rows: list[dict]) -> tuple[str, list, dict]:
    """The first axis's key, its values, and per line (its label) per x value the rows there."""
    axes = wanted["axes"]
    first = axes[0]["key"]
    xs = axes[0]["values"]
    several = [name for name in ("methods", "presets") if len(wanted[name]) > 1]
    lines: dict[str, dict] = {}
    for row in rows:
        values = dict((k, v) for k, v in row["values"])
        parts = [f"{a['key']}={values[a['key']]}" for a in axes[1:]]
        parts += [row[name[:-1]] for name in several]
        label = " ".join(str(p) for p in parts) or "all"
        lines.setdefault(label, {}).setdefault(_x_key(values[first]), []).append(row)
    return first, xs, lines


def _x_key(value) -> str:
    return repr(value)


def point(rows: list[dict], field: str) -> Point:
    """A metric's mean, min and max over the rows whose cell ran (NaN for a missing value)."""
    ok = [r for r in rows if r["status"] == "ok"]
    values = [float(v) for r in ok if (v := (r["score"] or {}).get(field)) is not None]
    error = next((r["status"] for r in rows if r["status"] != "ok"), None)
    if not values:
        return Point(math.nan, math.nan, math.nan, len(ok), len(rows), error)
    return Point(sum(values) / len(values), min(values), max(values), len(ok), len(rows), error)


def breaking_points(wanted: dict, rows: list[dict]) -> list[str]:
    """Per line, in words: the first value of the first axis at which the mean PCP over seeds is below
    `PCP_LIMIT` or the mean IDF1 below `IDF1_LIMIT` (or every cell failed), or that it holds throughout."""
    if not wanted["axes"]:
        return []
    first, xs, lines = _lines(wanted, rows)
    sentences = []
    for label, by_x in lines.items():
        verdict = None
        for n, x in enumerate(xs):
            here = by_x.get(_x_key(x), [])
            pcp, idf1 = point(here, "pcp"), point(here, "idf1")
            # (Below the bar at the first value tried is no breaking point: where it breaks is not in the grid.)
            where = f"breaks at {first} = {x}" if n else f"already below the bar at the first value, {first} = {x}"
            if here and pcp.ok == 0:
                verdict = f"{where}: every cell failed ({pcp.error})"
            elif pcp.mean < PCP_LIMIT:
                verdict = f"{where} (PCP {pcp.mean:.3f} < {PCP_LIMIT})"
            elif idf1.mean < IDF1_LIMIT:
                verdict = f"{where} (IDF1 {idf1.mean:.3f} < {IDF1_LIMIT})"
            if verdict:
                break
        verdict = verdict or (f"holds up to {first} = {xs[-1]} (mean PCP >= {PCP_LIMIT} and IDF1 >= {IDF1_LIMIT} "
                              "at every value)")
        sentences.append(f"{label}: {verdict}")
    return sentences


def _numeric(values) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def plot(wanted: dict, rows: list[dict], field: str, title: str, limit: float | None) -> bytes:
    """One metric against the first axis, one line per value of the others, mean and min–max over seeds (PNG)."""
    from matplotlib.figure import Figure

    first, xs, lines = _lines(wanted, rows)
    positions = xs if _numeric(xs) else list(range(len(xs)))
    figure = Figure(figsize=(6.4, 4.0), dpi=100, layout="constrained")
    ax = figure.add_subplot()
    for label, by_x in lines.items():
        points = [(p, point(by_x.get(_x_key(x), []), field)) for p, x in zip(positions, xs)]
        points = [(p, pt) for p, pt in points if not math.isnan(pt.mean)]
        if not points:
            continue
        ax.errorbar([p for p, _ in points], [pt.mean for _, pt in points],
                    yerr=[[pt.mean - pt.low for _, pt in points], [pt.high - pt.mean for _, pt in points]],
                    marker="o", capsize=3, label=label)
    if limit is not None:
        ax.axhline(limit, color="grey", linestyle="--", linewidth=1, label=f"limit {limit}")
    if not _numeric(xs):
        ax.set_xticks(positions, [str(x) for x in xs])
    ax.set_xlabel(first)
    ax.set_ylabel(title)
    ax.set_title(f"{title}\nmean over seeds, bars min–max ({wanted['scenario']}, {wanted['duration_s']:g} s a cell)",
                 fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", metadata={"Software": None})
    return buffer.getvalue()


def _fmt(pt: Point, digits: int) -> str:
    if math.isnan(pt.mean):
        return "–"
    spread = f" ({pt.low:.{digits}f}–{pt.high:.{digits}f})" if pt.high > pt.low else ""
    return f"{pt.mean:.{digits}f}{spread}"


def report_markdown(wanted: dict, rows: list[dict], plots: list[tuple[str, str]]) -> str:
    """report.md: the grid, the breaking points, the means over seeds, the failed cells and the plots."""
    axes = " × ".join(f"{a['key']} {', '.join(map(str, a['values']))}" for a in wanted["axes"])
    ok = sum(r["status"] == "ok" for r in rows)
    out = [
        f"# Sweep of {wanted['scenario']}",
        "",
        f"Grid: {axes + ' × ' if axes else ''}seeds {', '.join(map(str, wanted['seeds']))} × methods "
        f"{', '.join(wanted['methods'])} × presets {', '.join(wanted['presets'])}; {wanted['duration_s']:g} s "
        f"simulated per cell; crossview-testbed {wanted['version']}.",
        f"{len(rows)} cells: {ok} ok, {len(rows) - ok} failed.",
    ]
    breaks = breaking_points(wanted, rows)
    if breaks:
        out += ["", "## Breaking points", "",
                f"The first value of `{wanted['axes'][0]['key']}` at which the mean over seeds of PCP falls below "
                f"{PCP_LIMIT} or IDF1 below {IDF1_LIMIT}, per line:", ""]
        out += [f"- {b}" for b in breaks]
    if wanted["axes"]:
        first, xs, lines = _lines(wanted, rows)
        out += ["", "## Means over seeds (min–max)", "",
                f"| line | {first} | cells ok | PCP | IDF1 | MOTA | ID switches | false positives | tracker FPS |",
                "|---|---|---|---|---|---|---|---|---|"]
        for label, by_x in lines.items():
            for x in xs:
                here = by_x.get(_x_key(x), [])
                pts = {f: point(here, f) for f, _, _ in METRICS}
                out.append(f"| {label} | {x} | {pts['pcp'].ok}/{pts['pcp'].cells} | {_fmt(pts['pcp'], 3)} | "
                           f"{_fmt(pts['idf1'], 3)} | {_fmt(pts['mota'], 3)} | {_fmt(pts['id_switches'], 1)} | "
                           f"{_fmt(pts['false_positives'], 0)} | {_fmt(pts['tracker_fps'], 1)} |")
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        out += ["", "## Failed cells", ""] + [f"- {r['label']}: {r['status']}" for r in failed]
    if plots:
        out += ["", "## Plots", ""] + [f"![{title}]({path})" for path, title in plots]
    return "\n".join(out) + "\n"


def write_report(out: Path, wanted: dict, rows: list[dict]) -> None:
    """Writes `out/plots/*.png` (one per metric, when the grid has an axis) and `out/report.md`."""
    plots = []
    if wanted["axes"] and any(r["status"] == "ok" for r in rows):
        for field, title, limit in METRICS:
            path = f"plots/{field}.png"
            outputs.write_bytes(plot(wanted, rows, field, title, limit), Path(out) / path)
            plots.append((path, title))
    pipeline.write_text(report_markdown(wanted, rows, plots), Path(out) / "report.md")
