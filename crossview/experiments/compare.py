"""Several trackers over the same recordings, scored the same way: the rows, the table and a chart per metric.

A contender is a label and what produces its outputs: a `--method` (built in, registered or
`package.module:Class`) with a preset, or a result file per recording (`crossview.formats.results`). `compare_rows`
tracks and scores every contender on every recording and returns one row per pair (the score JSON with the
recording and the label); `write_report` writes them as a markdown table and a CSV with the best value of each
metric per recording marked, and one bar chart per metric (PNG). `crossview sweep --method` can call
`compare_rows` for its cells.
"""

from __future__ import annotations

import csv
import io
import logging
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from core.errors import CrossviewError
from crossview.outputs import write_bytes

log = logging.getLogger(__name__)

RESULT_PREFIX = "file:"
RECORDING_FIELD = "{recording}"


@dataclass(frozen=True)
class Metric:
    """A score JSON key as a column: its heading, whether more is better, and how it is printed."""

    key: str
    heading: str
    higher_is_better: bool
    fmt: str


METRICS = (
    Metric("pcp", "PCP", True, "{:.3f}"),
    Metric("mpjpe_mm", "MPJPE mm", False, "{:.1f}"),
    Metric("pck_100mm", "PCK 100 mm", True, "{:.3f}"),
    Metric("mota", "MOTA", True, "{:.3f}"),
    Metric("idf1", "IDF1", True, "{:.3f}"),
    Metric("id_switches", "ID switches", False, "{:d}"),
    Metric("hota", "HOTA", True, "{:.3f}"),
    Metric("association_accuracy", "assoc. acc.", True, "{:.3f}"),
    Metric("tracker_fps", "FPS", True, "{:.0f}"),
)


@dataclass(frozen=True)
class Contender:
    """One column of a comparison's rows: a label and a tracker method with its preset, or a result file.

    Attributes:
        label: the name in the table and the charts.
        method: a `--method` (see `crossview.plugins.resolve`); None for a result file.
        preset: the tracker preset the method is configured from.
        result: a result file's path; `{recording}` in it stands for the recording's file name without
            `.mcap`, so that one template names a file per recording.
    """

    label: str
    method: str | None = None
    preset: str = "store"
    result: str | None = None

    @classmethod
    def parse(cls, text: str) -> Contender:
        """`LABEL=SPEC` (or only SPEC, its own label) with SPEC one of `METHOD`, `METHOD@PRESET` or
        `file:PATH` (PATH may hold `{recording}`)."""
        label, sep, spec = text.partition("=")
        if not sep:
            label, spec = text, text
        if not label or not spec:
            raise CrossviewError(f"--tracker {text!r}: expected LABEL=METHOD[@PRESET] or LABEL=file:PATH")
        if spec.startswith(RESULT_PREFIX):
            return cls(label=label, result=spec[len(RESULT_PREFIX):])
        method, _, preset = spec.partition("@")
        return cls(label=label, method=method, preset=preset or "store")

    @property
    def spec(self) -> str:
        return f"{RESULT_PREFIX}{self.result}" if self.result is not None else f"{self.method}@{self.preset}"

    def result_path(self, recording: Path) -> Path:
        return Path(self.result.replace(RECORDING_FIELD, _stem(recording)))


def _stem(recording: Path) -> str:
    return Path(recording).name.removesuffix(".mcap")


def check(contenders: Sequence[Contender], recordings: Sequence[Path]) -> None:
    """Fails before any work on a duplicate label or recording name, a method that does not resolve, a preset
    that does not exist, or a missing result file."""
    from crossview.plugins import resolve
    from tracker.config import TrackerConfig

    if not contenders or not recordings:
        raise CrossviewError("compare: give at least one recording and one --tracker")
    for what, names in (("label", [c.label for c in contenders]), ("recording name", [_stem(r) for r in recordings])):
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise CrossviewError(f"compare: {what} {repeated[0]!r} is given twice; each must be unique")
    for contender in contenders:
        if contender.method is not None:
            resolve(contender.method)
            TrackerConfig.preset(contender.preset)
            continue
        for recording in recordings:
            path = contender.result_path(recording)
            if not path.is_file():
                raise CrossviewError(f"--tracker {contender.label}={contender.spec}: {path}: no such result file "
                                     f"for recording {recording}")


def compare_rows(contenders: Sequence[Contender], recordings: Sequence[Path], work_dir: Path, *,
                 progress: bool = False) -> list[dict]:
    """Tracks (into `work_dir`) and scores every contender on every recording.

    Returns:
        One row per (recording, contender), recordings outer: `recording`, `tracker`, `spec`, then every key
        of the score JSON (`docs/metrics.md`).
    """
    from crossview.outputs import kept_together

    recordings = [Path(r) for r in recordings]
    check(contenders, recordings)
    with kept_together(work_dir):  # one contender failing (or a signal) keeps none of the others' tracks
        return _rows(contenders, recordings, work_dir, progress)


def _rows(contenders, recordings, work_dir, progress) -> list[dict]:
    from crossview import pipeline

    rows = []
    for recording in recordings:
        for contender in contenders:
            if contender.method is None:
                outputs = contender.result_path(recording)
            else:
                outputs = Path(work_dir) / f"{_stem(recording)}.{_slug(contender.label)}.tracks.mcap"
                pipeline.track(recording, outputs, method=contender.method, preset=contender.preset,
                               progress=progress)
            _, score = pipeline.score(recording, outputs, progress=progress)
            log.info("%s on %s: PCP %s, IDF1 %s", contender.label, recording, score["pcp"], score["idf1"])
            rows.append({"recording": _stem(recording), "tracker": contender.label, "spec": contender.spec, **score})
    return rows


def _slug(label: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label)


def best_values(rows: Sequence[dict]) -> dict[tuple[str, str], float]:
    """(recording, metric key) -> the best value among the recording's rows (metrics with no value left out)."""
    best = {}
    for metric in METRICS:
        for recording in dict.fromkeys(r["recording"] for r in rows):
            values = [r[metric.key] for r in rows if r["recording"] == recording and r.get(metric.key) is not None]
            if values:
                best[recording, metric.key] = max(values) if metric.higher_is_better else min(values)
    return best


def _is_best(row: dict, metric: Metric, best: dict) -> bool:
    """Whether the row's value reads as the best of its recording: a tie as printed (0.98612 and 0.98608 are
    both 0.986) is marked for every tracker in it."""
    value, top = row.get(metric.key), best.get((row["recording"], metric.key))
    return value is not None and top is not None and metric.fmt.format(value) == metric.fmt.format(top)


def table(rows: Sequence[dict], marked: bool = True):
    """The rows as a `crossview.tables.Table`, one row per (recording, tracker), a missing metric `-`; `marked`: the
    best of each column per recording in Markdown bold."""
    from crossview.tables import Table

    best = best_values(rows)
    cells = []
    for row in rows:
        line = [row["recording"], row["tracker"]]
        for metric in METRICS:
            value = row.get(metric.key)
            text = "-" if value is None else metric.fmt.format(value)
            line.append(f"**{text}**" if marked and _is_best(row, metric, best) else text)
        cells.append(tuple(line))
    return Table(("recording", "tracker", *(m.heading for m in METRICS)), tuple(cells))


def markdown(rows: Sequence[dict]) -> str:
    """The rows as a markdown table (`table`), the best of each column per recording in bold."""
    return table(rows).markdown() + "\n"


def csv_text(rows: Sequence[dict]) -> str:
    """The rows as CSV: the metrics as plain numbers (empty when missing), and a last column `best` listing the
    metrics in which the row is the best of its recording (separated by spaces)."""
    best = best_values(rows)
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["recording", "tracker", "spec", *(m.key for m in METRICS), "best"])
    for row in rows:
        values = ["" if row.get(m.key) is None else row[m.key] for m in METRICS]
        marked = " ".join(m.key for m in METRICS if _is_best(row, m, best))
        writer.writerow([row["recording"], row["tracker"], row["spec"], *values, marked])
    return out.getvalue()


def bar_charts(rows: Sequence[dict], out_dir: Path) -> list[Path]:
    """One PNG per metric: bars grouped by recording, one bar per tracker; written atomically."""
    from matplotlib.figure import Figure

    recordings = list(dict.fromkeys(r["recording"] for r in rows))
    trackers = list(dict.fromkeys(r["tracker"] for r in rows))
    by_key = {(r["recording"], r["tracker"]): r for r in rows}
    width = 0.8 / len(trackers)
    paths = []
    for metric in METRICS:
        fig = Figure(figsize=(1.6 + 1.4 * len(recordings) * max(1, len(trackers)) / 3, 3.6), layout="constrained")
        ax = fig.add_subplot()
        for k, tracker in enumerate(trackers):
            values = [by_key.get((rec, tracker), {}).get(metric.key) for rec in recordings]
            xs = [i + (k - (len(trackers) - 1) / 2) * width for i in range(len(recordings))]
            ax.bar(xs, [float("nan") if v is None else v for v in values], width, label=tracker)
        ax.set_xticks(range(len(recordings)), recordings)
        ax.set_ylabel(metric.heading)
        ax.set_title(f"{metric.heading} ({'higher' if metric.higher_is_better else 'lower'} is better)")
        fig.legend(fontsize="small", loc="outside right upper")
        path = Path(out_dir) / f"{metric.key}.png"
        png = io.BytesIO()
        fig.savefig(png, format="png", dpi=100, metadata={"Software": None})
        write_bytes(png.getvalue(), path)
        paths.append(path)
    return paths


def write_report(rows: Sequence[dict], out_dir: Path) -> list[Path]:
    """compare.md, compare.csv and a chart per metric in `out_dir`; returns the paths written."""
    from crossview.pipeline import write_text

    out_dir = Path(out_dir)
    write_text(markdown(rows), out_dir / "compare.md")
    write_text(csv_text(rows), out_dir / "compare.csv")
    return [out_dir / "compare.md", out_dir / "compare.csv", *bar_charts(rows, out_dir)]
