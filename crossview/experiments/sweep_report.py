"""A sweep's report: means and 95 % intervals over seeds, where the bar holds, report.md and its matplotlib plots."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

from crossview import outputs, pipeline

PCP_LIMIT = 0.95
"""A value of the first axis meets the bar where the mean PCP over seeds is at least this ..."""
IDF1_LIMIT = 0.90
"""... and the mean IDF1 over seeds at least this."""
CONFIDENCE = 0.95
"""The intervals over seeds: Student's t interval of the mean at this confidence."""

METRICS = (
    ("pcp", "PCP", PCP_LIMIT),
    ("idf1", "IDF1", IDF1_LIMIT),
    ("mota", "MOTA", None),
    ("id_switches", "ID switches", None),
    ("false_positives", "false positives", None),
    ("tracker_fps", "tracker FPS (all cameras once)", None),
)
"""(score JSON field, title, limit drawn on its plot) of each plot."""
MEANS = ("pcp", "idf1", "mota", "id_switches", "false_positives", "hota", "mpjpe_mm")
"""The fields of results.json's "means": the plotted scores and HOTA and MPJPE, not the speeds (they vary from run
to run: timings.json has them)."""


@dataclass(frozen=True)
class Point:
    """One metric over the seeds of one x value of one line: the mean of the cells that ran and its 95 %
    interval (Student's t over the n values, mean ± t(0.975, n - 1) s / sqrt(n); NaN where none ran, the mean
    itself where one did), how many values, how many cells ran of how many, and the first failed cell's error."""

    mean: float
    low: float
    high: float
    ok: int
    cells: int
    error: str | None
    n: int = 0


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
    """A metric's mean and 95 % interval over the rows whose cell ran (NaN for a missing value)."""
    ok = [r for r in rows if r["status"] == "ok"]
    values = [float(v) for r in ok if (v := (r["score"] or {}).get(field)) is not None]
    error = next((r["status"] for r in rows if r["status"] != "ok"), None)
    if not values:
        return Point(math.nan, math.nan, math.nan, len(ok), len(rows), error)
    low, high = t_interval(values)
    return Point(sum(values) / len(values), low, high, len(ok), len(rows), error, len(values))


def t_interval(values: list[float], confidence: float = CONFIDENCE) -> tuple[float, float]:
    """(low, high) of Student's t interval of the mean of `values` (both the mean for one value)."""
    from scipy import stats

    n = len(values)
    mean = sum(values) / n
    if n < 2:
        return mean, mean
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    half = float(stats.t.ppf((1 + confidence) / 2, n - 1)) * sd / math.sqrt(n)
    return mean - half, mean + half


def means(wanted: dict, rows: list[dict]) -> list[dict]:
    """results.json's "means": per x value of each line (`_lines`), each metric's mean over seeds, its 95 %
    interval and how many values it has (the fields of `MEANS`)."""
    if not wanted["axes"]:
        lines = {"all": {None: rows}}
        first, xs = None, [None]
    else:
        first, xs, lines = _lines(wanted, rows)
    out = []
    for label, by_x in lines.items():
        for x in xs:
            here = by_x.get(_x_key(x), [])
            if not here:
                continue
            entry = {"line": label, **({first: x} if first else {}), "cells": len(here),
                     "ok": sum(r["status"] == "ok" for r in here)}
            for field in MEANS:
                pt = point(here, field)
                entry[field] = None if math.isnan(pt.mean) else {
                    "mean": pt.mean, "ci95": [pt.low, pt.high], "n": pt.n}
            out.append(entry)
    return out


def breaking_points(wanted: dict, rows: list[dict]) -> list[str]:
    """Per line, in words, where along the first axis the bar holds: the mean PCP over seeds at least
    `PCP_LIMIT` and the mean IDF1 at least `IDF1_LIMIT` (a value whose cells all failed does not meet it).
    Numeric values are taken in rising order, others as given; the bar may hold from a value on ("meets the bar
    from cameras = 30"), up to one ("... up to crowd.people = 10, not from 20"), at every value, at none, or
    at some (each named)."""
    if not wanted["axes"]:
        return []
    first, xs, lines = _lines(wanted, rows)
    order = sorted(xs) if _numeric(xs) else list(xs)
    bar = f"PCP >= {PCP_LIMIT} and IDF1 >= {IDF1_LIMIT}"
    sentences = []
    for label, by_x in lines.items():
        meets, why = {}, {}
        for x in order:
            here = by_x.get(_x_key(x), [])
            pcp, idf1 = point(here, "pcp"), point(here, "idf1")
            if not here:
                continue
            if pcp.ok == 0:
                meets[x], why[x] = False, f"every cell failed: {pcp.error}"
            elif not pcp.mean >= PCP_LIMIT:
                meets[x], why[x] = False, f"PCP {pcp.mean:.3f} < {PCP_LIMIT}"
            elif not idf1.mean >= IDF1_LIMIT:
                meets[x], why[x] = False, f"IDF1 {idf1.mean:.3f} < {IDF1_LIMIT}"
            else:
                meets[x], why[x] = True, f"PCP {pcp.mean:.3f}, IDF1 {idf1.mean:.3f}"
        tried = list(meets)
        held = [x for x in tried if meets[x]]
        if not tried:
            continue
        lo, hi = tried[0], tried[-1]
        if len(held) == len(tried):
            verdict = f"meets {bar} at every value, {first} = {lo} to {hi}"
        elif not held:
            verdict = f"below the bar ({bar}) at every value, {first} = {lo} to {hi} ({first} = {hi}: {why[hi]})"
        else:
            k = tried.index(held[0])
            if tried[k:] == held:  # below up to a value, then meets from the next one on
                verdict = (f"meets {bar} from {first} = {held[0]} ({why[held[0]]}); below at {first} = "
                           f"{tried[k - 1]} ({why[tried[k - 1]]})")
            elif tried[:len(held)] == held:  # meets up to a value, then breaks
                broke = tried[len(held)]
                verdict = f"meets {bar} up to {first} = {held[-1]}; breaks at {first} = {broke} ({why[broke]})"
            else:
                verdict = (f"meets {bar} at {first} = {', '.join(map(str, held))}; below at "
                           f"{', '.join(str(x) for x in tried if not meets[x])} (not monotonic along {first})")
        sentences.append(f"{label}: {verdict}")
    return sentences


def _numeric(values) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def plot(wanted: dict, rows: list[dict], field: str, title: str, limit: float | None) -> bytes:
    """One metric against the first axis, one line per value of the others, mean and 95 % interval over seeds
    (PNG); an axis of integers has integer ticks."""
    buffer = io.BytesIO()
    figure(wanted, rows, field, title, limit).savefig(buffer, format="png", metadata={"Software": None})
    return buffer.getvalue()


def figure(wanted: dict, rows: list[dict], field: str, title: str, limit: float | None):
    """The matplotlib Figure of `plot`."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    first, xs, lines = _lines(wanted, rows)
    positions = xs if _numeric(xs) else list(range(len(xs)))
    chart = Figure(figsize=(6.4, 4.0), dpi=100, layout="constrained")
    ax = chart.add_subplot()
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
    elif all(isinstance(x, int) for x in xs):  # (cameras, people: no tick at 12.5)
        if len(xs) <= 12:
            ax.set_xticks(sorted(xs), [str(x) for x in sorted(xs)])
        else:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel(first)
    ax.set_ylabel(title)
    ax.set_title(f"{title}\nmean over {len(wanted['seeds'])} seed{'s' if len(wanted['seeds']) != 1 else ''}, "
                 f"bars 95 % interval (t)\n{wanted['scenario']}, {wanted['duration_s']:g} s a cell"
                 f"{_warm_up(rows, ', scored from {} s')}", fontsize="medium")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    return chart


def _fmt(pt: Point, digits: int) -> str:
    if math.isnan(pt.mean):
        return "–"
    spread = f" ({pt.low:.{digits}f}–{pt.high:.{digits}f})" if pt.n > 1 else ""
    return f"{pt.mean:.{digits}f}{spread}"


def _warm_up(rows: list[dict], template: str) -> str:
    """The warm-up the cells left out (`from_s` of their scores), in `template`; "" when none was."""
    found = sorted({float(r["score"].get("from_s") or 0.0) for r in rows if r["status"] == "ok" and r["score"]})
    if not any(found):
        return ""
    return template.format(" or ".join(f"{f:g}" for f in found))


def report_markdown(wanted: dict, rows: list[dict], plots: list[tuple[str, str]]) -> str:
    """report.md: the grid, the breaking points, the means over seeds, the failed cells and the plots."""
    axes = " × ".join(f"{a['key']} {', '.join(map(str, a['values']))}" for a in wanted["axes"])
    ok = sum(r["status"] == "ok" for r in rows)
    out = [
        f"# Sweep of {wanted['scenario']}",
        "",
        f"Grid: {axes + ' × ' if axes else ''}seeds {', '.join(map(str, wanted['seeds']))} × methods "
        f"{', '.join(wanted['methods'])} × presets {', '.join(wanted['presets'])}; {wanted['duration_s']:g} s "
        f"simulated per cell{_warm_up(rows, ', scored from {} s on (the warm-up before is left out)')}; "
        f"crossview-testbed {wanted['version']}.",
        f"{len(rows)} cells: {ok} ok, {len(rows) - ok} failed.",
    ]
    breaks = breaking_points(wanted, rows)
    if breaks:
        out += ["", "## Where the bar holds", "",
                f"The values of `{wanted['axes'][0]['key']}` at which the mean over seeds of PCP is at least "
                f"{PCP_LIMIT} and of IDF1 at least {IDF1_LIMIT}, per line:", ""]
        out += [f"- {b}" for b in breaks]
    if wanted["axes"]:
        first, xs, lines = _lines(wanted, rows)
        out += ["", f"## Means over seeds ({int(100 * CONFIDENCE)} % interval, Student's t)", "",
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
