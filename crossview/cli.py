"""The `crossview` command line: run, generate, track and score a scenario, and the tools around them.

Every command prints a one-line error and exits with status 2 on bad input; only this module prints.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path

from core.errors import CrossviewError, Interrupted
from crossview.live import DEFAULT_PORT, parse_speed
from crossview.tables import emit

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT; SIGTERM and SIGHUP end with 128 + their number too
_ENDING_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
MAX_DURATION_S = 86400.0
"""Every `--duration` (simulated seconds): a day, as a scenario's duration_s (`sim.scenario.MAX_DURATION_S`),
checked as the option is read so that the line names the option, not the scenario file."""
MAX_SEED = 2**63 - 1
"""Every `--seed`: a scenario's seed (`sim.scenario.MAX_SEED`), which seeds numpy's generators."""


class _Ended(BaseException):
    """SIGTERM or SIGHUP, raised where the command is, so that it unwinds as from Ctrl-C: workers are
    stopped, temporary files removed, nothing left under a final name."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


_HELD: list[int] = []  # an ending signal held back while numba compiles (`_end`)
_RETRY_S = 0.05  # how often a held signal looks again whether compiling is over, seconds
_COMPILER = ("numba", "llvmlite")


def _end(signum, frame):
    """SIGINT, SIGTERM or SIGHUP: KeyboardInterrupt (`Interrupted`) or `_Ended` raised where the command is,
    unless numba is compiling there (a cold cache: a first run, a new version). An exception raised inside its
    compiler is lost where llvmlite calls back through ctypes (which prints "Exception ignored" and goes on:
    the command then ran to its end) or leaves numba half-built (a later call fails with a traceback). The
    signal is then held, and raised once the compiler has returned (SIGALRM looks again every `_RETRY_S`)."""
    if _in_compiler(frame):
        _HELD[:] = [signum]
        signal.setitimer(signal.ITIMER_REAL, _RETRY_S)
        return
    _HELD.clear()
    if signum == signal.SIGINT:
        raise Interrupted
    raise _Ended(signum)


def _retry_held(signum, frame):
    """SIGALRM while a signal is held (`_end`)."""
    if _HELD:
        _end(_HELD[-1], frame)


def _in_compiler(frame) -> bool:
    """Whether Python code of numba or llvmlite is on the stack below `frame`."""
    while frame is not None:
        if frame.f_globals.get("__name__", "").partition(".")[0] in _COMPILER:
            return True
        frame = frame.f_back
    return False


class _Parser(argparse.ArgumentParser):
    """argparse with the project's exit status for bad arguments and a one-line message."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


class _TopParser(_Parser):
    """The `crossview` parser: an unknown option before (or without) a command is named, where argparse would first
    say that a command is required."""

    def parse_args(self, args=None, namespace=None):
        self._given = list(sys.argv[1:] if args is None else args)
        return super().parse_args(args, namespace)

    def error(self, message):
        if "required: COMMAND" in message:
            known = {"-h", "--help", "--version", *(s for flags, _ in GLOBAL_OPTIONS for s in flags)}
            unknown = [a for a in getattr(self, "_given", []) if a.startswith("-") and a.partition("=")[0] not in known]
            if unknown:
                message = f"unrecognized arguments: {' '.join(unknown)}"
        super().error(message)


class _Version(argparse.Action):
    """`--version`: the installed package's version (looked up only when asked)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from crossview.recording import software_version

        sys.stdout.write(f"crossview {software_version()}\n")
        parser.exit(0)


GLOBAL_OPTIONS = (
    (("-v", "--verbose"), "log progress details"),
    (("--no-progress",), "hide progress bars"),
)
"""Options of every command, given before or after its name (`build_parser`)."""


class _ReaderGoneStdout:
    """The command's stdout, which a reader that closed it (`crossview run ... | head -1`) cannot end the command
    through: once a write finds the pipe closed (BrokenPipeError), the rest of what it prints goes nowhere
    (stdout is pointed at the null device) and the command runs on to write its outputs, ending with its own
    status. Everything else is stdout's."""

    def __init__(self, inner):
        self._inner = inner
        self.reader_gone = False

    def write(self, text: str) -> int:
        if not self.reader_gone:
            try:
                return self._inner.write(text)
            except BrokenPipeError:
                self._drop()
        return len(text)

    def flush(self) -> None:
        if not self.reader_gone:
            try:
                self._inner.flush()
            except BrokenPipeError:
                self._drop()

    def _drop(self) -> None:
        self.reader_gone = True
        try:  # (what stdout still holds is flushed at exit: into the null device, not a closed pipe)
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, self._inner.fileno())
            os.close(null)
        except (OSError, ValueError, AttributeError):
            pass

    def __getattr__(self, name):
        return getattr(self._inner, name)


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text} must be > 0")
    return value


def _frame_rate(text: str) -> float:
    """A frame rate, as a scenario's clock.fps: in (0, 1000] frames per second (an infinite one stamped every
    frame 0)."""
    from sim.clock import MAX_FPS

    value = _positive_float(text)
    if not value <= MAX_FPS:
        raise argparse.ArgumentTypeError(f"{text} must be in (0, {MAX_FPS:g}] frames per second")
    return value


def _duration_s(text: str) -> float:
    value = _positive_float(text)
    if not value <= MAX_DURATION_S:
        raise argparse.ArgumentTypeError(f"{text} must be at most {MAX_DURATION_S:g} s (a day), as a scenario's "
                                         "duration_s")
    return value


def _minutes_as_s(text: str) -> float:
    """world-stats' old --minutes, in seconds."""
    value = _positive_float(text)
    if not value <= MAX_DURATION_S / 60:
        raise argparse.ArgumentTypeError(f"{text} must be at most {MAX_DURATION_S / 60:g} minutes (a day)")
    return 60.0 * value


def _non_negative_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"{text!r} must be a number of seconds >= 0")
    return value


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} must be >= 0")
    return value


def _seed(text: str) -> int:
    value = _non_negative_int(text)
    if value > MAX_SEED:
        raise argparse.ArgumentTypeError(f"{text} must be in [0, 2^63 - 1], as a scenario's seed")
    return value


def _positive_int(text: str) -> int:
    value = _non_negative_int(text)
    if value == 0:
        raise argparse.ArgumentTypeError("0 must be >= 1")
    return value


def add_output(p: argparse.ArgumentParser, help: str, *, required: bool = True, default: Path | None = None,
               old: tuple[str, ...] = (), metavar: str = "PATH") -> None:
    """Adds `-o/--output`: a command's one main output file or folder, spelt the same on every command.

    Args:
        p: the command's parser.
        help: what is written there (and its default, when not required).
        required: whether the command needs it.
        default: the path when it is not given.
        old: the spellings it had before (`--out`, `--json`), still accepted for one version but hidden from
            --help; one beside -o/--output is refused in one line, exit 2.
        metavar: the placeholder in --help (PATH, DIR, REC.mcap, ...).
    """
    group = p.add_mutually_exclusive_group(required=required)
    group.add_argument("-o", "--output", type=Path, default=default, metavar=metavar, help=help)
    for spelling in old:
        group.add_argument(spelling, dest="output", type=Path, default=argparse.SUPPRESS, metavar=metavar,
                           help=argparse.SUPPRESS)


def add_format(p: argparse.ArgumentParser) -> None:
    """Adds `--format text|json|markdown`: how a command that prints a table prints it, and writes it with -o
    (`crossview.tables`: one rule for every such command)."""
    from crossview.tables import FORMATS

    p.add_argument("--format", choices=FORMATS, help="how to print the table: text (default), json or markdown; a "
                   "file written with -o takes this format, else its suffix's (.json, .md), else text")


def _say(args, line: str) -> None:
    """A line about what the command did: on stdout beside a text table, on stderr when stdout holds a JSON or
    Markdown document (`--format`)."""
    print(line, file=sys.stdout if getattr(args, "format", None) in (None, "text") else sys.stderr, flush=True)


def _scenario_options(p):
    """The options of the commands that simulate a scenario (`run`, `generate`)."""
    p.add_argument("--seed", type=_seed, help="seed (default: the scenario's)")
    p.add_argument("--duration", type=_duration_s, help="simulated seconds (default: the scenario's)")
    p.add_argument("--people", type=_non_negative_int, help="number of people (overrides [crowd] people)")
    p.add_argument("--cameras", type=_positive_int, help="number of cameras, as a grid fitted to the floor")


def _live_options(p, what):
    """The live server's options; `what` words `--live` (None: the command always serves, as `serve`)."""
    if what:
        p.add_argument("--live", action="store_true", help=f"{what} live on a Foxglove WebSocket server as it "
                       "runs (pip install '.[live]'; docs/recording-format.md)")
    p.add_argument("--port", type=_non_negative_int, default=DEFAULT_PORT, help="the live server's port (0: any "
                   f"free port, printed; default {DEFAULT_PORT})")
    p.add_argument("--speed", type=parse_speed, default=1.0, metavar="FACTOR|max",
                   help="pace of the live view: times real time, or max for as fast as it runs (default 1)")


def _tracker_options(p):
    """The options choosing a tracker (`run`, `track`)."""
    p.add_argument("--method", default="crossview", metavar="METHOD",
                   help="crossview, baseline, a name registered under the entry-point group crossview.trackers, "
                   "or package.module:Class of the tracker shape (docs/plugins.md); default crossview")
    p.add_argument(
        "--preset",
        default="store",
        help="tracker preset: campus, shelf, store, or campus-paper, shelf-paper, store-paper for Table S2 "
        "verbatim (default store)",
    )
    p.add_argument("--config", type=Path, help="TOML file of tracker parameters over the preset")


def _run_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", nargs="?", help="scenario file or shipped name (default store_layout1)")
    _scenario_options(p)
    _tracker_options(p)
    add_output(p, "folder for NAME.mcap, NAME.tracks.mcap, NAME.score.json (default recordings/)",
               required=False, default=Path("recordings"), old=("--out",), metavar="DIR")
    p.add_argument("--json", type=Path, help="score JSON path (default OUTPUT/NAME.score.json)")
    p.add_argument("--from", dest="from_s", type=_non_negative_float, metavar="S", help="score from S seconds on, "
                   "leaving out the warm-up before (default: the warm-up rule of docs/metrics.md)")
    _zone_options(p)
    _live_options(p, "publish the recording and its tracks, each frame tracked as it is made,")


def _scenarios_args(p: argparse.ArgumentParser) -> None:
    show = p.add_mutually_exclusive_group()
    show.add_argument("--show", metavar="SCENARIO", help="print a scenario with every key resolved (TOML)")
    show.add_argument("--reference", action="store_true", help="print every key's meaning, unit, default and range "
                      "(docs/scenarios.md)")


def _generate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario file or shipped name")
    add_output(p, "recording to write (.mcap)", metavar="REC.mcap")
    _scenario_options(p)
    p.add_argument("--images", type=_positive_float, metavar="RATE", help="store RATE rendered JPEG pictures per "
                   "second per camera (at most the frame rate; needs the render extra; docs/rendering.md)")
    p.add_argument("--gl", choices=("egl", "osmesa"), help="MuJoCo's OpenGL backend for --images (default: "
                   "$MUJOCO_GL when it names one, else EGL, then OSMesa)")
    _live_options(p, "publish the recording")


def _coverage_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario file or shipped name")
    add_output(p, "the map to write (.png; default: the shares only)", required=False, metavar="MAP.png")
    p.add_argument("--cameras", type=_positive_int, help="number of cameras, as a grid fitted to the floor")
    p.add_argument("--seed", type=_seed, help="seed of the cameras' position jitter (default: the "
                   "scenario's)")
    p.add_argument("--people", type=_non_negative_int, help="the crowd whose occlusion to predict (default: the "
                   "scenario's [crowd] people)")
    p.add_argument("--figures", type=Path, metavar="FILE", help="write the figures here too (in --format, else "
                   "as its suffix says: .json, .md, else text)")
    add_format(p)


def _plan_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario file or shipped name (its rig a ceiling grid)")
    p.add_argument("--target-pcp", type=float, required=True, metavar="P", help="the PCP to reach, in (0, 1]")
    p.add_argument("--people", type=_non_negative_int, help="the crowd to plan for (default: the scenario's)")
    p.add_argument("--heights", metavar="H1,H2", help="mounting heights to try, metres above the floor (default: "
                   "the scenario's)")
    p.add_argument("--lenses", metavar="DEG1,DEG2", help="lenses to try, horizontal field of view in degrees "
                   "(default: the scenario's)")
    p.add_argument("--max-cameras", type=_positive_int, help="the most cameras to try (default: one per m² of "
                   "floor, at least 16)")
    add_output(p, "the plan to write (in --format, else as its suffix says: .json, .md, else text)",
               metavar="PLAN.json")
    add_format(p)
    p.add_argument("--map", type=Path, metavar="MAP.png", help="the recommended rig's coverage map (default: "
                   "PLAN.png beside the plan)")
    p.add_argument("--confirm", action="store_true", help="measure the recommended rig with the tracker (a sweep "
                   "of --seeds x --duration into PLAN.confirm/cN/ beside the plan), then walk the grid ladder to "
                   "the fewest cameras measured to meet the target, which becomes the recommendation")
    p.add_argument("--seeds", default="0,1,2", help="with --confirm: comma-separated seeds (default 0,1,2)")
    p.add_argument("--duration", type=_duration_s, default=30.0, help="with --confirm: simulated seconds per "
                   "seed (default 30)")
    p.add_argument("--workers", type=_positive_int, help="with --confirm: local worker processes (default: the "
                   "cores)")


def _track_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="recording (.mcap) made by generate or convert")
    add_output(p, "tracks file to write (.mcap)", metavar="TRACKS.mcap")
    _tracker_options(p)
    _zone_options(p)


def _zone_options(p):
    """The options tracking a store as zones (`track`, `run`)."""
    p.add_argument("--zones", metavar="auto|N", help="track the store as N zones, each by its own tracker, "
                   "identities handed over at their borders (auto: about one zone per 60 cameras, the cut of fewest "
                   "zone cameras; docs/zones.md)")
    p.add_argument("--overlap", type=_positive_float, default=2.0, metavar="M", help="with --zones: how far "
                   "neighbouring zones overlap, metres (at least 2; default 2)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive_int, help="with --zones: local worker processes holding the "
                       "zones (default: the cores, at most one per zone; 1 tracks every zone in this process)")
    where.add_argument("--ray", nargs="?", const="", metavar="ADDRESS", help="with --zones: the zones as Ray "
                       "actors: alone, on a local instance; with ADDRESS, on that cluster (pip install '.[ray]')")


def _zones_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario file or shipped name")
    p.add_argument("--zones", default="auto", metavar="auto|N", help="number of zones (default auto: about one per 60 "
                   "cameras, the cut of fewest zone cameras)")
    p.add_argument("--overlap", type=_positive_float, default=2.0, metavar="M", help="how far neighbouring zones "
                   "overlap, metres (at least 2; default 2)")
    p.add_argument("--cameras", type=_positive_int, help="number of cameras, as a grid fitted to the floor")
    p.add_argument("--seed", type=_non_negative_int, help="seed of the cameras' position jitter (default: the "
                   "scenario's)")
    add_output(p, "the map to write (.png; default: the table only)", required=False, metavar="MAP.png")
    p.add_argument("--figures", type=Path, metavar="FILE", help="write the zones here too (in --format, else as "
                   "its suffix says: .json, .md, else text)")
    add_format(p)


def _score_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="the recording (.mcap) the tracks were made from")
    p.add_argument("tracks", type=Path, help="tracks file (.mcap), result_3d.json or JSON lines "
                   "(docs/recording-format.md)")
    add_output(p, "write the score here too (in --format, else as its suffix says: .json, .md, else text)",
               required=False, old=("--json",))
    add_format(p)
    p.add_argument("--from", dest="from_s", type=_non_negative_float, default=0.0, metavar="S",
                   help="leave out a warm-up: truth and tracks before S seconds are not scored (default 0)")
    p.add_argument("--map", type=Path, metavar="MAP.png", help="draw where and when the tracker failed: floor "
                   "heat maps of misses, false positives and ID switches, and each person's time line")


def _info_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=Path, help="a recording or tracks file (.mcap)")
    p.add_argument("--allow-truncated", action="store_true", help="report the readable prefix of a cut file")
    p.add_argument("--summary-only", action="store_true",
                   help="describe a complete file from its summary alone, without reading every chunk and "
                        "checking its CRC")


def _render_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="recording (.mcap) made by generate")
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--camera", metavar="NAME", help="one camera's view")
    what.add_argument("--contact-sheet", action="store_true", help="every camera's view in a labelled grid")
    what.add_argument("--top-down", action="store_true", help="the plan: shelves, each camera's field of view on "
                      "the floor, true and tracked paths (from --from to --to, or 0 to --time), id switches")
    p.add_argument("--time", type=float, metavar="T", help="the instant, seconds since the recording's start")
    p.add_argument("--from", dest="from_s", type=float, metavar="T0", help="start of a clip or a top-down range, s")
    p.add_argument("--to", dest="to_s", type=float, metavar="T1", help="end of a clip or a top-down range, s")
    p.add_argument("--tracks", type=Path, help="tracks file of the recording: draw the tracked skeletons")
    add_output(p, "picture (.png, .jpg) or, with --from/--to, clip (.gif, .mp4)")
    p.add_argument("--fps", type=_positive_float, default=10.0, help="images per second of a clip (default 10)")
    p.add_argument("--tile-width", type=_positive_int, default=320, help="width of a contact sheet's tiles, pixels "
                   "(default 320)")
    p.add_argument("--gl", choices=("egl", "osmesa"), help="MuJoCo's OpenGL backend (default: $MUJOCO_GL when it "
                   "names one, else EGL, then OSMesa)")


def _serve_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="recording (.mcap) made by generate")
    p.add_argument("tracks", type=Path, nargs="?", help="tracks file (.mcap) made from the recording")
    _live_options(p, None)
    p.add_argument("--play", action="store_true", help="start playing at once (default: paused until a client "
                   "plays)")


def _compare_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recordings", nargs="+", type=Path, help="recordings (.mcap) to track and score")
    p.add_argument("--tracker", action="append", required=True, metavar="LABEL=SPEC",
                   help="repeat for each tracker; SPEC is a --method (crossview, baseline, pkg.module:Class, a "
                   "registered name) with an optional @PRESET, or file:PATH of a result file ({recording} in PATH "
                   "is the recording's name without .mcap)")
    add_output(p, "folder for compare.md, compare.csv, the charts and tracks", old=("--out",), metavar="DIR")
    add_format(p)


def _sweep_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="base scenario file or shipped name")
    p.add_argument("--set", dest="axes", action="append", type=_sweep_axis, default=[], metavar="KEY=V1,V2,...",
                   help="an axis: any scenario key by its dotted name (crowd.people, clock.fps, ...); repeatable, "
                   "the first is the x of the plots, the second the lines")
    p.add_argument("--people", dest="axes", action="append", type=lambda t: ("crowd.people", t), metavar="N1,N2",
                   help="axis of crowd sizes (--set crowd.people=...)")
    p.add_argument("--cameras", dest="axes", action="append", type=lambda t: ("cameras", t), metavar="N1,N2",
                   help="axis of camera counts, each a grid fitted to the floor")
    p.add_argument("--seeds", help="comma-separated seeds (default: the scenario's seed)")
    p.add_argument("--method", default="crossview", metavar="[LABEL=]METHOD,...",
                   help="comma-separated tracker methods, each a --method of track (a plug-in as pkg.module:Class), "
                   "optionally LABEL=METHOD to name it in the results (default crossview)")
    p.add_argument("--preset", default="store", help="comma-separated tracker presets (default store)")
    p.add_argument("--duration", type=_duration_s, help="simulated seconds per cell (default: the scenario's)")
    p.add_argument("--from", dest="from_s", type=_non_negative_float, metavar="S", help="leave the first S seconds "
                   "of each cell out of its score (default: the warm-up rule of docs/metrics.md, min(5 s, half a "
                   "cell))")
    p.add_argument("--zones", metavar="auto|N", help="track each cell as N zones (2 m overlap), one after another in "
                   "the cell's worker, as `track --zones` does (docs/zones.md); default one tracker")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=_positive_int, help="local worker processes (default: the cores; 1 runs "
                       "the cells one after another in this process)")
    where.add_argument("--ray", nargs="?", const="", metavar="ADDRESS", help="run the cells as Ray tasks: alone, "
                       "on a local instance; with ADDRESS, on that cluster (pip install '.[ray]')")
    add_output(p, "output folder (a rerun into it resumes)", old=("--out",), metavar="DIR")
    p.add_argument("--keep-recordings", action="store_true", help="keep each cell's recording and write "
                   "manifest.json (for crossview verify)")


def _verify_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("folder", type=Path, help="a sweep folder with manifest.json (sweep --keep-recordings)")
    p.add_argument("--cells", type=_positive_int, help="check a fixed sample of this many (default: all)")


def _ablate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("experiments", nargs="*", metavar="EXPERIMENT",
                   help="affinity, reconstruction, frame-rate, speed, single-view, priors (default: all)")
    p.add_argument("--quick", action="store_true", help="one seed, short runs, fewer points (about 2 minutes)")
    p.add_argument("--workers", type=_positive_int, help="local worker processes of the sweeps (default: the "
                   "cores; 1 runs them in this process)")
    add_output(p, "output folder (a rerun into it resumes)", old=("--out",), metavar="DIR")


def _export_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=Path, help="tracks file (crossview-json, jsonl, bvh, trc, c3d, mot) or recording "
                   "(dataset, openpose, bvh, trc, c3d, mot, coco)")
    p.add_argument("--format", default="crossview-json", choices=EXPORT_FORMATS,
                   help="crossview-json: tracks as result_3d.json (default); jsonl: tracks as JSON lines; dataset: "
                   "a recording as a folder of calibration.json, detection.json, annotation_2d.json, "
                   "annotation_3d.json, scene.json; openpose: the same with OpenPose JSON folders for detection.json; "
                   "bvh, trc, c3d: the truth's or the tracks' people, one file per person (BVH: Y up, cm, rotations "
                   "Zrotation Xrotation Yrotation; TRC: Pose2Sim's, Y up, m; C3D: z up, mm, needs the extra .[c3d]); "
                   "mot: TrackEval's MOTChallenge folder of the instants `score` compares (tracks need --recording); "
                   "coco: COCO keypoints per camera, projected truth and detections")
    p.add_argument("--recording", type=Path, metavar="REC.mcap", help="mot: the recording the tracks were made from")
    p.add_argument("--from", dest="from_s", type=_non_negative_float, metavar="S", help="mot: leave out the first S "
                   "seconds, as `score --from S` does (default 0)")
    p.add_argument("--rate", type=_positive_float, metavar="HZ", help="bvh, trc, c3d of a tracks file: the rate of "
                   "the grid the tracks are sampled on (default 30; a recording's truth keeps its own 100 Hz)")
    add_output(p, "the file, or a new folder (dataset, openpose, bvh, trc, c3d, mot, coco)")


def _convert_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", type=Path, help="folder of calibration.json and detection.json, annotation_2d.json or "
                   "one folder of OpenPose *_keypoints.json per camera")
    add_output(p, "recording to write (.mcap)", metavar="REC.mcap")
    p.add_argument("--fps", type=_frame_rate, help="OpenPose folders: frame rate for the stamps that "
                   "timestamps.json does not give (stamp = frame number / fps)")


def _evaluate_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("dataset", type=Path, help="dataset folder (calibration.json, annotation_3d.json, ...)")
    p.add_argument("result", type=Path, help="result_3d.json in the dataset layout")
    add_output(p, "write the evaluation here too (in --format, else as its suffix says: .json, .md, else text)",
               required=False, metavar="FILE")
    add_format(p)


def _per_camera_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="the recording (.mcap) the tracks were made from")
    p.add_argument("tracks", type=Path, help="cross-view tracks file made from the recording")
    add_output(p, "write the table here too (in --format, else as its suffix says: .json, .md, else text)",
               required=False, old=("--json",))
    add_format(p)


def _detector_stats_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, help="a recording with 3D truth: `crossview generate`, or `crossview "
                   "convert` of a dataset folder with annotation_3d.json")
    add_output(p, "write the figures here too (in --format, else as its suffix says: .json, .md, else text)",
               required=False, old=("--json",), metavar="FILE")
    add_format(p)
    p.add_argument("--reference", default="shelf-openpose", metavar="FILE.json|shelf-openpose", help="what to "
                   "print the figures beside, its column headed by its source: a `detector-stats -o` file (of a "
                   "recording like this one), or shelf-openpose, real OpenPose on Shelf's 400 px people (default)")


def _fit_detector_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("recording", type=Path, nargs="?", help="a recording whose detections to fit (synthetic, or "
                   "converted from a dataset with 3D truth); leave out with --target")
    add_output(p, "the profile file to write (TOML)", metavar="PROFILE.toml")
    p.add_argument("--target", metavar="FILE.json|shelf-openpose", help="fit to a statistics table instead of a "
                   "recording: a `detector-stats -o` file, or shelf-openpose, real OpenPose on the Shelf dataset "
                   "(shipped)")
    p.add_argument("--scenario", help="the rig to simulate (default: the recording's own scenario; with --target: "
                   "shelf)")
    p.add_argument("--start", default="typical", help="the profile the fit starts from: a shipped name or a profile "
                   "file (default typical)")
    p.add_argument("--seed", type=_seed, help="seed of every round (default: the recording's, else the "
                   "scenario's)")
    p.add_argument("--duration", type=_duration_s, default=20.0, help="simulated seconds per round (default 20)")
    p.add_argument("--rounds", type=_positive_int, default=8, help="rounds of simulate, measure, update (default 8)")
    p.add_argument("--figures", type=Path, metavar="FILE", help="write the fitted statistics beside the target here "
                   "(in --format, else as its suffix says: .json, .md, else text)")
    add_format(p)


def _world_stats_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenario", help="scenario file or shipped name")
    p.add_argument("--seed", type=_seed, help="seed (default: the scenario's)")
    duration = p.add_mutually_exclusive_group()
    duration.add_argument("--duration", type=_duration_s, default=600.0, help="simulated seconds (default 600, "
                          f"at most {MAX_DURATION_S:g})")
    duration.add_argument("--minutes", dest="duration", type=_minutes_as_s, default=argparse.SUPPRESS,
                          help=argparse.SUPPRESS)  # (the old spelling, for one version)
    add_output(p, "write the figures here too (in --format, else as its suffix says: .json, .md, else text)",
               required=False, metavar="FILE")
    add_format(p)


def _bench_args(p: argparse.ArgumentParser) -> None:
    add_output(p, "write the figures here (in --format, else as its suffix says: .json, .md, else text)",
               required=False, old=("--json",))
    add_format(p)
    p.add_argument("--markdown", type=Path, help="write them as the benchmarks page here (docs/benchmarks.md)")
    p.add_argument("--duration", type=_duration_s, help="simulated seconds per case (default 20; 10 with --scale)")
    p.add_argument("--scale", action="store_true", help="the tracker at crowd scale instead (28/16 to 240/200 "
                   "cameras/people, and time per round against cameras): docs/benchmarks.md's last section")
    p.add_argument("--budget", type=_positive_float, default=300.0, help="with --scale: most seconds of tracking "
                   "timed per case (the rest of a slower case's stream is left unscored; default 300)")


COMMAND_ARGUMENTS = (
    ("run", _run_args,
     "generate, track and score a scenario (default: the built-in store)"),
    ("scenarios", _scenarios_args,
     "list the shipped scenarios, print one resolved, or the key reference"),
    ("generate", _generate_args,
     "simulate a scenario into a recording"),
    ("coverage", _coverage_args,
     "how many cameras see each floor cell: the shares of the walkable floor "
     "seen by 1, 2, 3 or more cameras, and a top-down map"),
    ("plan", _plan_args,
     "how many cameras a store needs: the fewest ceiling cameras whose predicted "
     "tracking meets a PCP target, with --confirm measured by a short sweep"),
    ("track", _track_args,
     "run a tracker over a recording"),
    ("zones", _zones_args,
     "cut a store's floor into zones for `track --zones`: each zone's cell and "
     "cameras, and a top-down map"),
    ("score", _score_args,
     "score a tracks file or a result file against its recording"),
    ("info", _info_args,
     "describe a recording or tracks file"),
    ("render", _render_args,
     "pictures of what the cameras saw, with the detections and tracks drawn on"),
    ("serve", _serve_args,
     "replay a recording (and its tracks) on a Foxglove WebSocket server, with play, "
     "pause, seek and speed (pip install '.[live]')"),
    ("compare", _compare_args,
     "several trackers over the same recordings: one table, a chart per metric"),
    ("sweep", _sweep_args,
     "run a grid of generate-track-score cells (scenario keys x seeds x methods)"),
    ("verify", _verify_args,
     "regenerate a kept sweep's recordings and check their bytes"),
    ("ablate", _ablate_args,
     "the paper's ablations (Tables S1, 4, 5, Figures 5, 6) and the tracker's body "
     "and joint priors into one report"),
    ("export", _export_args,
     "write tracks or a recording for other tools: the paper's dataset layout, "
     "motion (BVH, TRC, C3D), MOTChallenge, COCO keypoints (docs/exports.md)"),
    ("convert", _convert_args,
     "turn a dataset in the paper's layout into a recording"),
    ("evaluate", _evaluate_args,
     "score a result in the paper's dataset layout with its PCP protocol"),
    ("per-camera", _per_camera_args,
     "per-camera MOTA and IDF1: single-view baseline against cross-view "
     "(the paper's Table 5)"),
    ("detector-stats", _detector_stats_args,
     "measure a recording's 2D detections against its projected 3D truth, "
     "beside a reference (default real OpenPose on Shelf)"),
    ("fit-detector", _fit_detector_args,
     "fit a detector profile to a recording's detector statistics (or to "
     "real OpenPose on Shelf), by simulating the rig with candidate profiles"),
    ("world-stats", _world_stats_args,
     "measure the crowd: clearances, foot slip, activities, speeds, sim speed"),
    ("bench", _bench_args,
     "measure tracker and simulator speed on the shipped stores"),
)
"""Every command: its name, the function adding its arguments, its --help line; in the order a user meets them: a
first run, the scenarios, a recording and its cameras' coverage, tracking and scoring it, looking at it, comparing
and sweeping, then the dataset tools."""


def build_parser() -> argparse.ArgumentParser:
    parser = _TopParser(prog="crossview", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action=_Version, help="print the version and exit")
    for flags, text in GLOBAL_OPTIONS:
        parser.add_argument(*flags, action="store_true", help=text)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser, metavar="COMMAND")
    for name, add_arguments, text in COMMAND_ARGUMENTS:
        add_arguments(sub.add_parser(name, help=text))
    parser.commands = sub.choices  # name -> its parser (the tests compare them with the docs)
    for command in sub.choices.values():
        for flags, text in GLOBAL_OPTIONS:  # (SUPPRESS: not given here, the value before the command stands)
            command.add_argument(*flags, action="store_true", default=argparse.SUPPRESS, help=text)
    return parser


def _cmd_ablate(args) -> None:
    from crossview.experiments import ablate

    command = " ".join(["crossview ablate", *args.experiments, *(["--quick"] if args.quick else []), "-o DIR"])
    summary = ablate.run(args.output, args.experiments, quick=args.quick, workers=args.workers,
                         progress=not args.no_progress, command=command)
    print(f"ablate: {len(summary.experiments)} experiments in {summary.wall_s / 60:.1f} min; report: {summary.report}")


def _sweep_axis(text: str) -> tuple[str, str]:
    key, sep, values = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is not KEY=V1,V2,... (for example crowd.people=10,25)")
    return key.strip(), values


def _cmd_sweep(args) -> None:
    from crossview import pipeline, plugins
    from crossview.experiments import sweep
    from tracker.config import PRESETS

    axes = tuple(sweep.parse_axis(key, text) for key, text in args.axes)
    keys = [a.key for a in axes]
    repeated = next((k for k in keys if keys.count(k) > 1), None)
    if repeated:
        raise CrossviewError(f"--set {repeated}: given twice; give one axis per key")
    if args.duration is not None and "duration_s" in keys:
        raise CrossviewError("--duration: duration_s is also an axis (--set duration_s=...); give one")
    methods = sweep.parse_names("--method", args.method)
    labels = [sweep.split_method(m)[0] for m in methods]
    repeated = next((label for label in labels if labels.count(label) > 1), None)
    if repeated:
        raise CrossviewError(f"--method: the label {repeated!r} is given twice; give each method its own")
    for method in methods:  # each a tracker `crossview track` can run (a bad one is named before any cell runs)
        plugins.resolve(sweep.split_method(method)[1])
    seeds = sweep.parse_seeds(args.seeds) if args.seeds is not None else (pipeline.load_scenario(args.scenario).seed,)
    spec = sweep.SweepSpec(
        scenario=args.scenario, axes=axes, seeds=seeds,
        methods=methods,
        presets=sweep.parse_names("--preset", args.preset, PRESETS), duration_s=args.duration,
        warm_up_s=args.from_s, zones=args.zones,
    )
    if args.zones is not None:  # (auto or a whole number; whether the rig holds it is each cell's to say)
        from crossview import zoned

        zoned.zone_count(args.zones)
    if args.ray is not None:
        executor = sweep.Executor.RAY
    else:
        executor = sweep.Executor.SERIAL if args.workers == 1 else sweep.Executor.POOL
    summary = sweep.run_sweep(spec, args.output, executor=executor, workers=args.workers, ray_address=args.ray or None,
                              keep_recordings=args.keep_recordings, progress=not args.no_progress)
    print(f"sweep: {summary.cells} cells, {summary.skipped} already finished (skipped), {summary.ran} run, "
          f"{summary.failed} failed, in {summary.wall_s:.1f} s")
    print(f"results: {summary.out / 'results.json'}, {summary.out / 'results.csv'}, {summary.out / 'report.md'}")


def _cmd_verify(args) -> None:
    from crossview.experiments import sweep

    results = sweep.verify(args.folder, cells=args.cells, progress=not args.no_progress)
    for r in results:
        held = r.file_sha256[:16] if r.file_sha256 else "missing"
        print(f"{'ok      ' if r.matches else 'MISMATCH'} {r.file}: manifest {r.expected_sha256[:16]}, file {held}, "
              f"regenerated {r.regenerated_sha256[:16]}")
    bad = sum(not r.matches for r in results)
    if bad:
        raise CrossviewError(f"{args.folder}: {bad} of {len(results)} recordings differ from manifest.json")
    print(f"verify: {len(results)} of {len(results)} recordings match manifest.json")


def _cmd_run(args) -> None:
    from crossview import pipeline, scoring

    scenario = pipeline.load_scenario(
        args.scenario, seed=args.seed, duration_s=args.duration, people=args.people, cameras=args.cameras
    )
    _say_cameras(args, scenario)
    out = args.output
    rec_path = out / f"{scenario.name}.mcap"
    tracks_path = out / f"{scenario.name}.tracks.mcap"
    json_path = args.json or out / f"{scenario.name}.score.json"
    pipeline.check_writable(rec_path)
    pipeline.check_writable(tracks_path, inputs=(rec_path,))
    pipeline.check_writable(json_path, inputs=(rec_path, tracks_path))
    pipeline.tracker_config(args.preset, args.config)  # (a bad tracker config is found before generating)
    _check_zone_options(args)
    if args.zones is not None:  # (zones the rig cannot hold are found before generating)
        from crossview import zoned
        from sim.cameras import build_rig
        from sim.rng import child_rng
        from sim.store import StoreGeometry

        zoned.cut(build_rig(scenario, child_rng(scenario.seed, "cameras")),
                  StoreGeometry(scenario.store, name=scenario.where).boxes, args.zones, args.overlap)
    progress = not args.no_progress
    with _live(args) as stream:
        if stream:  # (tracked as the frames are made: `pipeline.live_run`; not with --zones, `_check_zone_options`)
            gen, trk = pipeline.live_run(scenario, rec_path, tracks_path, method=args.method, preset=args.preset,
                                         config_path=args.config, progress=progress, live=stream())
        else:
            gen = pipeline.generate(scenario, rec_path, progress=progress)
        print(f"generated {gen.path}: {gen.num_cameras} cameras, {gen.num_frames} camera frames in {gen.wall_s:.1f} s "
              f"({_speed(gen)})")
        if args.zones is not None:
            args.recording, args.output = rec_path, tracks_path
            _track_zoned(args, prefix="tracked   ")
        else:
            if not stream:
                trk = pipeline.track(rec_path, tracks_path, method=args.method, preset=args.preset,
                                     config_path=args.config, progress=progress)
            print(f"tracked   {trk.path}: {_updates_and_speed(trk, 'at {fps:.1f} FPS (all cameras once)')}")
    from_s = scoring.default_from_s(scenario.duration_s) if args.from_s is None else args.from_s
    report, result = pipeline.score(rec_path, tracks_path, progress=progress, from_s=from_s)
    pipeline.write_json(result, json_path, inputs=(rec_path, tracks_path))
    print(report.table())
    print(f"score JSON: {json_path}")
    _warn_coverage(scenario)


def _cmd_scenarios(args) -> None:
    from sim import scenario as scenario_mod
    from sim.scenario_reference import reference_markdown

    if args.reference:
        print(reference_markdown(), end="")
    elif args.show:
        print(scenario_mod.resolved_toml(scenario_mod.load(args.show)), end="")
    else:
        rows = [(path.stem, scenario_mod.load(path)) for path in scenario_mod.shipped()]
        width = max(len(name) for name, _ in rows)
        for name, scenario in rows:
            print(f"{name:<{width}}  {scenario.description}")
        print(f"(in {scenario_mod.SCENARIO_DIR}; `crossview scenarios --show NAME` prints one in full)")


def _say_cameras(args, scenario) -> None:
    """What `--cameras N` chose: the first N of a real rig's cameras, or the grid fitted to the floor."""
    if getattr(args, "cameras", None) is None:
        return
    if scenario.cameras.calibration:
        _say(args, f"--cameras {args.cameras}: the first {args.cameras} cameras of {scenario.cameras.calibration}")
    else:
        _say(args, f"--cameras {args.cameras}: a grid of {scenario.cameras.rows} rows x {scenario.cameras.cols} "
             f"columns over the {scenario.store.width_m:g} m x {scenario.store.depth_m:g} m floor")


def _warn_coverage(scenario) -> None:
    """One line on stderr when the rig sees too little of the floor with two cameras (`crossview.measure.coverage`);
    said once the command has done its work, so that bad input stays the one line on stderr."""
    from crossview.measure.coverage import warning as coverage_warning

    warning = coverage_warning(scenario)  # (the upper bound alone: the prediction costs minutes at 1,000 cameras)
    if warning:
        print(warning, file=sys.stderr)


def _cmd_coverage(args) -> None:
    from crossview import pipeline
    from crossview.measure import coverage

    scenario = pipeline.load_scenario(args.scenario, seed=args.seed, cameras=args.cameras)
    _say_cameras(args, scenario)
    for path in (args.output, args.figures):
        if path:
            pipeline.check_writable(path)
    cov = coverage.coverage(scenario, people=args.people)
    emit(cov.as_dict(), fmt=args.format, output=args.figures, text="\n".join(cov.lines()))
    if args.output:
        _say(args, f"map: {coverage.write_map(cov, args.output)}")
    warning = cov.warning()
    if warning:
        print(warning, file=sys.stderr)


def _cmd_plan(args) -> None:
    from crossview import pipeline
    from crossview.experiments import plan, sweep
    from crossview.measure import coverage

    seeds = sweep.parse_seeds(args.seeds)
    heights = plan.parse_floats("--heights", args.heights, 0.0, 20.0, "metres") if args.heights else None
    lenses = plan.parse_floats("--lenses", args.lenses, 0.0, 179.0, "degrees") if args.lenses else None
    map_path = args.map or args.output.with_suffix(".png")
    confirm_dir = args.output.with_suffix(".confirm")
    pipeline.check_writable(args.output)
    pipeline.check_writable(map_path, inputs=(args.output,))
    progress = None if args.no_progress else (lambda line: print(f"  {line}", file=sys.stderr))
    result = plan.plan(args.scenario, args.target_pcp, people=args.people, heights_m=heights, lenses_deg=lenses,
                       max_cameras=args.max_cameras, progress=progress)
    rec = result.recommended
    if args.confirm:
        result = plan.Plan(**{**vars(result), "confirmed": plan.confirm(
            args.scenario, result, confirm_dir, people=args.people, seeds=seeds, duration_s=args.duration,
            workers=args.workers, progress=progress)})
    _, grid, _ = result.answer  # (the map is the recommendation's: with --confirm, the measured rig's)
    chosen = rec if grid == rec.grid else plan.predict_candidate(
        args.scenario, pipeline.load_scenario(args.scenario), grid, rec.height_m, rec.hfov_deg, args.people)
    _say(args, f"map: {coverage.write_map(chosen.coverage, map_path)}")
    head = f"{result.scenario}, {result.people} people, target PCP {result.target_pcp:g}:"
    words = [f"recommended: {rec.cameras} cameras ({rec.grid[0]} x {rec.grid[1]}) at {rec.height_m:g} m with "
             f"{rec.hfov_deg:g} deg lenses, predicted PCP {rec.predicted_pcp:.3f}"]
    if result.confirmed:
        c = result.confirmed
        for m in c["measured"]:
            verdict = "meets the target" if m["meets_target"] else "does NOT meet the target"
            words.append(f"measured: {m['cameras']} cameras ({m['grid'][0]} x {m['grid'][1]}): PCP "
                         f"{m['pcp_mean']:.3f} (95 % interval {m['pcp_ci95'][0]:.3f} to {m['pcp_ci95'][1]:.3f}, "
                         f"seeds {', '.join(map(str, m['seeds']))}, {m['duration_s']:g} s each): {verdict} "
                         f"{result.target_pcp:g}")
        if c["meets_target"]:
            below = c["steps_below_prediction"]
            moved = ("the prediction's answer" if below == 0 else
                     f"{abs(below)} grid step{'' if abs(below) == 1 else 's'} "
                     f"{'below' if below > 0 else 'above'} the prediction's {rec.cameras}")
            words.append(f"confirmed: {c['cameras']} cameras ({c['grid'][0]} x {c['grid'][1]}) are the fewest "
                         f"measured to meet PCP {result.target_pcp:g}: {c['pcp_mean']:.3f} ({moved})")
        else:
            words.append(f"confirmed: no rig measured meets PCP {result.target_pcp:g}; the most measured, "
                         f"{c['cameras']} cameras, gave {c['pcp_mean']:.3f}")
    emit(result.as_dict(), fmt=args.format, output=args.output, what="plan",
         text="\n".join([head, result.table(), *words]), blocks=[head, result.candidates_table(), *words])


def _cmd_generate(args) -> None:
    from crossview import pipeline

    scenario = pipeline.load_scenario(
        args.scenario, seed=args.seed, duration_s=args.duration, people=args.people, cameras=args.cameras
    )
    _say_cameras(args, scenario)
    with _live(args) as stream:
        gen = pipeline.generate(scenario, args.output, progress=not args.no_progress, images_per_s=args.images,
                                gl=args.gl, live=stream and stream())
    print(f"{gen.path}: {gen.num_cameras} cameras, {gen.num_frames} camera frames in {gen.wall_s:.1f} s "
          f"({_speed(gen)})")
    if gen.images:
        print(f"{gen.images} pictures rendered in {gen.images_s:.1f} s ({1000 * gen.images_s / gen.images:.0f} ms "
              "each: render, lens, JPEG)")
    _warn_coverage(scenario)


def _live(args):
    """The live server of `--live` (`crossview.live.live_stream`): a context giving a maker of paced streams, one per
    file written, or None without --live."""
    from crossview import live

    return live.live_stream(args.port if args.live else None, args.speed, lambda line: print(line, flush=True))


def _cmd_serve(args) -> None:
    from crossview import live

    files, start_ns, end_ns = live.open_files(args.recording, args.tracks)
    try:
        live.serve(files, args.port, args.speed, start_ns, end_ns, lambda line: print(line, flush=True),
                   play=args.play)
    except Interrupted:  # (Ctrl-C: how a server is ended; it wrote nothing)
        print("serve: stopped")


def _speed(gen) -> str:
    return (f"{gen.realtime_factor:.1f}x real time; {gen.running_realtime_factor:.1f}x after {gen.startup_s:.2f} s "
            "of start-up")


def _cmd_track(args) -> None:
    from crossview import pipeline

    _check_zone_options(args)
    if args.zones is not None:
        _track_zoned(args)
        return
    trk = pipeline.track(
        args.recording, args.output, method=args.method, preset=args.preset, config_path=args.config,
        progress=not args.no_progress,
    )
    print(f"{trk.path}: {_updates_and_speed(trk, ', {fps:.1f} FPS (all cameras once), {frames:.0f} camera frames/s')}")


def _updates_and_speed(trk, template: str) -> str:
    """`N updates` and the speed as `template` words it, or, when no camera frame was tracked (a stream too
    short to hold one), that no speed was measured (was "0 updates at nan FPS")."""
    if trk.updates == 0 or not trk.tracker_s > 0:
        return f"{trk.updates} updates (no camera frame in the stream: no speed measured)"
    return f"{trk.updates} updates" + (" " if template.startswith("at") else "") + template.format(
        fps=trk.tracker_fps, frames=trk.camera_frames_per_s)


def _check_zone_options(args) -> None:
    """--workers and --ray only with --zones; `run --zones` not with --live (the zones' merged tracks are
    written, not published)."""
    if args.zones is None and (args.workers is not None or args.ray is not None):
        raise CrossviewError(f"{'--workers' if args.workers is not None else '--ray'}: only with --zones (one "
                             "tracker runs in this process)")
    if args.zones is not None and getattr(args, "live", False):
        raise CrossviewError("--live: not with --zones (the zones' merged tracks are written to the tracks file, "
                             "not published; leave out one of them)")


def _track_zoned(args, prefix: str = "") -> None:
    from core import processes
    from crossview import zoned
    from crossview.parallel import Executor, cluster

    if args.ray is not None:
        executor, workers = Executor.RAY, args.workers or processes.usable_cores()
    else:
        workers = args.workers or processes.usable_cores()
        executor = Executor.SERIAL if workers == 1 else Executor.POOL
    with cluster.session(args.ray or None, connect=executor is Executor.RAY):
        result = zoned.track_zoned(args.recording, args.output, zones_text=args.zones, overlap_m=args.overlap,
                                   executor=executor, workers=workers, method=args.method, preset=args.preset,
                                   config_path=args.config, progress=not args.no_progress)
    summed = sum(result.zone_tracker_s)
    print(f"{prefix}{result.path}: {result.updates} camera frames, {len(result.zone_cameras)} zones (cameras "
          f"{', '.join(map(str, result.zone_cameras))}) on {result.workers} worker(s), {result.handovers} hand-overs; "
          f"{result.camera_frames_per_s:.0f} camera frames/s wall-clock, {result.tracker_fps_wall:.1f} FPS (all "
          f"cameras once); zones' update time {summed:.1f} s in all ({result.summed_frames_per_s:.0f} camera "
          "frames/s on one core)")
    for z, (cameras, frames, spent) in enumerate(zip(result.zone_cameras, result.zone_frames, result.zone_tracker_s,
                                                     strict=True)):
        speed = f"{frames / spent:.0f} camera frames/s" if spent > 0 else "no speed measured"
        print(f"  zone {z}: {cameras} cameras, {frames} camera frames, update {spent:.1f} s ({speed})")
    print(f"  peak memory: {result.peak_memory / 2**20:.0f} MiB this process; workers "
          f"{', '.join(f'{m / 2**20:.0f}' for m in result.worker_peak_memory)} MiB")


def _cmd_zones(args) -> None:
    from crossview import pipeline, zoned
    from crossview.tables import Table
    from sim.cameras import build_rig
    from sim.rng import child_rng
    from sim.store import StoreGeometry

    scenario = pipeline.load_scenario(args.scenario, seed=args.seed, cameras=args.cameras)
    for path in (args.output, args.figures):
        if path:
            pipeline.check_writable(path)
    cameras = build_rig(scenario, child_rng(scenario.seed, "cameras"))
    boxes = StoreGeometry(scenario.store, name=scenario.where).boxes
    cut = zoned.cut(cameras, boxes, args.zones, args.overlap)
    memberships = sum(len(z.cameras) for z in cut)
    head = (f"{scenario.name}: {len(cut)} zones, {len(cameras)} cameras, {memberships} zone cameras "
            f"({memberships / len(cameras):.2f} per camera: the overlap's cost)")
    rows = [f"  zone {z.index}: x {z.cell[0]:.1f}..{z.cell[2]:.1f} m, y {z.cell[1]:.1f}..{z.cell[3]:.1f} m, "
            f"{len(z.cameras)} cameras" for z in cut]
    figures = {"scenario": scenario.name, "cameras": len(cameras), "zone_cameras": memberships,
               "overlap_m": args.overlap,
               "zones": [{"index": z.index, "cell_m": [float(v) for v in z.cell], "cameras": len(z.cameras)}
                         for z in cut]}
    emit(figures, fmt=args.format, output=args.figures, text="\n".join([head, *rows]),
         blocks=[head, Table(("zone", "x from m", "x to m", "y from m", "y to m", "cameras"),
                             tuple((str(z.index), *(f"{v:.1f}" for v in (z.cell[0], z.cell[2], z.cell[1], z.cell[3])),
                                    str(len(z.cameras))) for z in cut))])
    if args.output:
        _say(args, f"map: {zoned.write_map(scenario.name, boxes, cameras, cut, args.overlap, args.output)}")


def _cmd_score(args) -> None:
    from crossview import pipeline

    inputs = (args.recording, args.tracks)
    if args.output:
        pipeline.check_writable(args.output, inputs=inputs)
    if args.map:
        pipeline.check_writable(args.map, inputs=(*inputs, *([args.output] if args.output else [])))
    report, result = pipeline.score(args.recording, args.tracks, progress=not args.no_progress, from_s=args.from_s)
    emit(result, fmt=args.format, output=args.output, what="score", text=report.table(),
         blocks=report.markdown_blocks(), inputs=inputs)
    if args.map:
        pipeline.write_score_map(result, args.recording, args.map, inputs=inputs)
        _say(args, f"map: {args.map}")


def _cmd_info(args) -> None:
    from crossview import recording

    print(recording.format_info(recording.info(args.file, allow_truncated=args.allow_truncated,
                                                        check=not args.summary_only)))


def _cmd_detector_stats(args) -> None:
    from crossview import pipeline
    from crossview.measure.detector_stats import (
        SHELF_OPENPOSE_NAME,
        detector_stats_blocks,
        format_detector_stats,
        recording_detector_stats,
        reference,
    )

    inputs = (args.recording, *(() if args.reference == SHELF_OPENPOSE_NAME else (Path(args.reference),)))
    if args.output:
        pipeline.check_writable(args.output, inputs=inputs)
    ref = reference(args.reference)  # (a bad file refused before measuring)
    stats = recording_detector_stats(args.recording, progress=not args.no_progress)
    emit({**stats, "reference": {"label": ref.label, "where": ref.where}}, fmt=args.format, output=args.output,
         text=format_detector_stats(stats, ref), blocks=detector_stats_blocks(stats, ref), inputs=inputs)


def _cmd_fit_detector(args) -> None:
    from crossview import pipeline, recording
    from crossview.measure.detector_fit import NOT_TARGETS, REACHED, deviations, fit, unreached
    from crossview.measure.detector_stats import (
        SHELF_OPENPOSE_NAME,
        Reference,
        detector_stats_blocks,
        format_detector_stats,
        recording_detector_stats,
        reference,
    )
    from sim import scenario as scenario_mod
    from sim.sensing.profiles import DetectorProfile, profile_file_text, profile_params

    if (args.recording is None) == (args.target is None):
        raise CrossviewError("fit-detector: give a recording to fit, or --target FILE.json|shelf-openpose (not both)")
    target_file = None if args.target in (None, SHELF_OPENPOSE_NAME) else Path(args.target)
    pipeline.check_writable(args.output, inputs=() if target_file is None else (target_file,))
    if args.figures:
        pipeline.check_writable(args.figures, inputs=(args.output, *(() if target_file is None else (target_file,))))
    start = profile_params(args.start)  # (a bad --start refused before any measuring)
    seed = args.seed
    if args.recording is not None:
        target = recording_detector_stats(args.recording)
        where, label = f"{args.recording}", args.recording.name  # (fitted to the recording's own statistics)
        if args.scenario is None:
            header = recording.open_recording(args.recording).header
            if not header.scenario_text:
                raise CrossviewError(f"{args.recording}: holds no scenario to simulate (a converted dataset); give "
                                     "--scenario, a scenario of the rig it was recorded on")
            scenario = scenario_mod.from_source_text(header.scenario_text, header.scenario_name, str(args.recording))
            seed = header.seed if seed is None else seed
        else:
            scenario = pipeline.load_scenario(args.scenario)
    else:
        ref = reference(args.target)
        target, where, label = ref.stats, ref.where, ref.label
        if target_file is None:
            # Its false-positive people count a person the annotation leaves out: no target
            # (crossview/measure/data/README.md).
            target = {k: v for k, v in target.items() if k not in NOT_TARGETS}
        scenario = pipeline.load_scenario(args.scenario or "shelf")
    seed = scenario.seed if seed is None else seed

    def report(k, result):
        (key, group), worst = max(deviations(result.stats, target).items(), key=lambda kv: abs(kv[1]))
        _say(args, f"round {k + 1}/{args.rounds}: largest deviation {100 * worst:+.1f} % ({key}"
             f"{'' if group is None else ', ' + group})")

    best = fit(target, scenario, start, seed=seed, duration_s=args.duration, rounds=args.rounds, on_round=report)
    missed = unreached(best, target)
    unreached_lines = [f"rows further than {100 * REACHED:g} % from the target: {len(missed) or 'none'}",
                       *(f"  {key}{'' if group is None else ', ' + group}: {100 * dev:+.1f} %: {why}"
                         for key, group, dev, why in missed)]
    figures = {"reference": where, "fitted": best.stats, "target": target,
               "unreached": [{"key": key, "group": group, "deviation": dev, "why": why}
                             for key, group, dev, why in missed]}
    emit(figures, fmt=args.format, output=args.figures, what="fitted statistics",
         text="\n".join([format_detector_stats(best.stats, Reference(target, label, where)),
                         *unreached_lines]),
         blocks=[*detector_stats_blocks(best.stats, Reference(target, label, where)),
                 *(line.strip() for line in unreached_lines)],
         inputs=() if target_file is None else (target_file,))
    (key, group), worst = max(deviations(best.stats, target).items(), key=lambda kv: abs(kv[1]))
    comment = (f"Detector profile fitted by `crossview fit-detector` to {where}, on {scenario.name} (seed {seed}, "
               f"{args.duration:g} s a round, {args.rounds} rounds, from {args.start}).\nLargest deviation of a "
               f"row from the target: {100 * worst:+.1f} % ({key}{'' if group is None else ', ' + group}).")
    pipeline.write_text(profile_file_text(best.params, DetectorProfile.TYPICAL, comment), args.output)
    _say(args, f"{args.output}: the fitted profile (largest deviation {100 * best.worst:.1f} %)")


def _cmd_world_stats(args) -> None:
    from crossview import pipeline
    from crossview.measure.world_stats import measure

    if args.output:
        pipeline.check_writable(args.output)
    scenario = pipeline.load_scenario(args.scenario, seed=args.seed)
    emit(measure(scenario, duration_s=args.duration), fmt=args.format, output=args.output)


def _cmd_evaluate(args) -> None:
    from crossview import pipeline
    from crossview.scoring.campus import evaluate, evaluation_blocks, format_evaluation

    if args.output:
        pipeline.check_writable(args.output, inputs=(args.dataset, args.result))
    result = evaluate(args.dataset, args.result)
    emit(result, fmt=args.format, output=args.output, what="evaluation", text=format_evaluation(result),
         blocks=evaluation_blocks(result), inputs=(args.dataset, args.result))


EXPORT_FORMATS = ("crossview-json", "jsonl", "dataset", "openpose", "bvh", "trc", "c3d", "mot", "coco")


def _cmd_export(args) -> None:
    from crossview import pipeline, recording
    from crossview.formats.datasets import export_dataset, export_openpose, write_result_3d

    if args.format != "mot" and args.recording is not None:
        raise CrossviewError(f"--recording {args.recording}: only --format mot reads a tracks file's recording")
    if args.format != "mot" and args.from_s is not None:
        raise CrossviewError(f"--from {args.from_s:g}: only --format mot leaves out a warm-up")
    if args.format not in ("bvh", "trc", "c3d") and args.rate is not None:
        raise CrossviewError(f"--rate {args.rate:g}: only --format bvh, trc and c3d resample tracks")
    if args.format in ("bvh", "trc", "c3d"):
        from crossview.formats.motion import export_motion

        for line in export_motion(args.file, args.output, args.format, args.rate):
            print(args.output / line)
        return
    if args.format == "mot":
        from core.records import watched_floor
        from crossview.formats.tracking import export_mot
        from crossview.recording.reader import read_kind
        from crossview.recording.schemas import KIND_RECORDING

        if read_kind(args.file) == KIND_RECORDING:
            rec, tracks = recording.open_recording(args.file), None
        elif args.recording is None:
            raise CrossviewError(f"{args.file}: a tracks file; --format mot needs its recording too (--recording "
                                 "REC.mcap): the truth and the scored area are there")
        else:
            rec, tracks = pipeline.open_run(args.recording, args.file)
        print(export_mot(rec, tracks, args.output, watched_floor(rec.boxes), from_s=args.from_s or 0.0))
        return
    if args.format == "coco":
        from crossview.formats.tracking import export_coco

        print(export_coco(args.file, args.output))
        return
    if args.format in ("dataset", "openpose"):
        write = export_dataset if args.format == "dataset" else export_openpose
        frames = write(args.file, args.output)
        print(f"{args.output}: {frames} camera frames written in the {args.format} layout")
        return
    pipeline.check_writable(args.output, inputs=(args.file,))
    tracks = recording.open_tracks(args.file)
    if args.format == "jsonl":
        from crossview.formats.results import json_lines

        pipeline.write_text(json_lines(tracks.outputs()), args.output, inputs=(args.file,))
    else:
        write_result_3d(tracks.outputs(), args.output, inputs=(args.file,))
    print(f"{args.output}: written")


def _cmd_convert(args) -> None:
    from crossview import pipeline
    from crossview.formats.datasets import convert
    from sim import scenario as scenario_mod

    inputs = (*Path(args.dataset).glob("*.json"), *Path(args.dataset).glob("*/*_keypoints.json"))
    pipeline.check_writable(args.output, inputs=inputs)
    convert(args.dataset, args.output, fps=args.fps, inputs=inputs, check_scenario=scenario_mod.from_source_text)
    print(f"{args.output}: written")


def _cmd_per_camera(args) -> None:
    from crossview import pipeline
    from crossview.experiments.table5 import paper_means_line, per_camera_table

    if args.output:
        pipeline.check_writable(args.output, inputs=(args.recording, args.tracks))
    table = per_camera_table(args.recording, args.tracks, progress=not args.no_progress)
    rows = table.table()
    emit(table.to_json(), fmt=args.format, output=args.output, what="table",
         text=rows.text() + "\n\n" + paper_means_line(), blocks=[rows, paper_means_line()],
         inputs=(args.recording, args.tracks))


def _cmd_compare(args) -> None:
    from crossview import pipeline
    from crossview.experiments import compare
    from crossview.outputs import kept_together

    contenders = [compare.Contender.parse(text) for text in args.tracker]
    compare.check(contenders, args.recordings)
    for name in ("compare.md", "compare.csv", *(f"{m.key}.png" for m in compare.METRICS)):
        pipeline.check_writable(args.output / name, inputs=tuple(args.recordings))
    with kept_together(args.output):  # the tracks, the table and the charts: all of them, or none
        rows = compare.compare_rows(contenders, args.recordings, args.output / "tracks",
                                    progress=not args.no_progress)
        written = compare.write_report(rows, args.output)
    emit({"rows": rows}, fmt=args.format, text=compare.table(rows, marked=False).text(),
         blocks=[compare.table(rows)])
    _say(args, f"written: {', '.join(str(p) for p in written)}")


def _cmd_bench(args) -> None:
    from crossview import pipeline

    if args.output:
        pipeline.check_writable(args.output)

    def show(payload, text):
        emit(payload, fmt=args.format, output=args.output, text=text)

    if args.scale:
        from crossview.experiments import bench_scale

        bench_scale.main(duration_s=args.duration or 10.0, progress=not args.no_progress,
                         markdown_path=args.markdown, budget_s=args.budget, show=show)
    else:
        from crossview.experiments import bench

        bench.main(duration_s=args.duration or 20.0, progress=not args.no_progress, markdown_path=args.markdown,
                   show=show)
    if args.markdown:
        _say(args, f"written: {args.markdown}")


def _cmd_render(args) -> None:
    from crossview.pictures.render import Request, render

    done = render(Request(
        recording=args.recording, output=args.output, tracks=args.tracks, camera=args.camera,
        contact_sheet=args.contact_sheet, top_down=args.top_down, time_s=args.time, from_s=args.from_s,
        to_s=args.to_s, gl=args.gl, fps=args.fps, tile_width_px=args.tile_width, progress=not args.no_progress,
    ))
    timing = done.timing
    rendered = (f"; {timing.renders} camera views rendered in {timing.render_s:.2f} s "
                f"({1000 * timing.per_image_s:.0f} ms each)") if timing.renders else ""
    print(f"{done.path}: {done.images} image{'s' if done.images != 1 else ''}{rendered}")


_OUTPUT_DESTS = frozenset({"output", "out", "json", "markdown", "map", "figures"})
"""The options that name what a command writes; every other path it is given is something it reads."""


def _command_inputs(args) -> tuple[Path, ...]:
    """Every file the command reads, known before it runs: each path it is given that is not an output (a
    folder given as input stands for the files in it and its sub-folders, as a dataset's), its scenario and
    the calibration that names, its tracker config and the module files of its plug-in trackers. Each must be
    a regular file or folder (a FIFO would hang its reader; a device is no input). Declared for the command's
    run (`crossview.outputs.command_inputs`), so that no output of it can be one of them.

    Raises:
        CrossviewError: an input that is neither a regular file nor a folder, or a plug-in that does not load.
    """
    from crossview import pipeline, plugins
    from crossview.formats.json_input import check_input_file
    from sim.sensing.profiles import is_profile_file

    found: list[Path] = []
    for dest, value in vars(args).items():
        if dest in _OUTPUT_DESTS:
            continue
        for item in value if isinstance(value, list) else [value]:
            if isinstance(item, Path):
                found.append(item)
                if item.is_dir():
                    found.extend(p for p in (*item.glob("*"), *item.glob("*/*")) if p.is_file())
    if isinstance(getattr(args, "scenario", None), str) or args.command == "run":
        found.extend(pipeline.scenario_files(args.scenario))
    if is_profile_file(getattr(args, "start", None)):  # (fit-detector's starting profile)
        found.append(Path(args.start))
    for option in ("target", "reference"):  # (fit-detector's and detector-stats' statistics files)
        value = getattr(args, option, None)
        if isinstance(value, str) and value != "shelf-openpose":  # (scenarios' --reference is a switch)
            found.append(Path(value))
    methods = [m.strip() for m in getattr(args, "method", "").split(",")]
    for text in getattr(args, "tracker", None) or []:
        from crossview.experiments.compare import Contender

        contender = Contender.parse(text)
        if contender.method is not None:
            methods.append(contender.method)
        else:
            found.extend(contender.result_path(r) for r in args.recordings)
    for method in methods:
        method = method.partition("=")[2].strip() or method  # (a sweep's LABEL=METHOD)
        if method and method not in plugins.BUILTIN_METHODS:
            found.extend(Path(f) for f in plugins.resolve(method).source_files)
    for path in found:
        check_input_file(path)
    return tuple(found)


COMMANDS = {
    "run": _cmd_run,
    "generate": _cmd_generate,
    "coverage": _cmd_coverage,
    "plan": _cmd_plan,
    "track": _cmd_track,
    "zones": _cmd_zones,
    "score": _cmd_score,
    "info": _cmd_info,
    "detector-stats": _cmd_detector_stats,
    "fit-detector": _cmd_fit_detector,
    "world-stats": _cmd_world_stats,
    "scenarios": _cmd_scenarios,
    "evaluate": _cmd_evaluate,
    "export": _cmd_export,
    "convert": _cmd_convert,
    "per-camera": _cmd_per_camera,
    "compare": _cmd_compare,
    "bench": _cmd_bench,
    "render": _cmd_render,
    "serve": _cmd_serve,
    "sweep": _cmd_sweep,
    "verify": _cmd_verify,
    "ablate": _cmd_ablate,
}


TABLE_COMMANDS = ("score", "per-camera", "detector-stats", "fit-detector", "world-stats", "coverage", "compare",
                  "bench", "evaluate", "zones", "plan")
"""The commands that print a table, each with `--format` and `-o` (`crossview.tables`; README.md, "Commands")."""


COMPILING_LINE = "crossview: compiling numeric kernels (once, about a minute)"


def _saying_when_compiling(command: str):
    """A context in which one line goes to stderr as numba starts compiling the project's kernels, when some are not
    in its cache yet (`core.jit.cold_cache`: a first run is otherwise silent while they compile); said only once
    compiling starts, so that bad input found before stays the one line on stderr. Nothing for a command that calls
    no kernel."""
    import contextlib

    if command in _NO_KERNELS:
        return contextlib.nullcontext()
    from core import jit

    if not jit.cold_cache():
        return contextlib.nullcontext()
    return jit.saying_when_compiling(lambda: print(COMPILING_LINE, file=sys.stderr, flush=True))


_NO_KERNELS = frozenset({"scenarios", "info", "serve", "evaluate", "export", "convert"})
"""The commands that call no compiled kernel (`_saying_when_compiling`)."""


# The tracker and the simulator work on many tiny matrices: BLAS threads only add contention there, so
# one thread per process unless the user asked otherwise (set before numpy is first imported).
_SINGLE_THREAD_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
# No command renders with MuJoCo: unless the user chose a backend, MuJoCo's import skips looking for one
# (which the simulation worker's start-up, and so the whole generation, would wait for).
_NO_RENDERING_ENV = ("MUJOCO_GL", "disable")


def main(argv: list[str] | None = None) -> int:
    for name in _SINGLE_THREAD_ENV:
        os.environ.setdefault(name, "1")
    os.environ.setdefault(*_NO_RENDERING_ENV)
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:  # --help (0) or a bad argument (2, message already printed)
        return int(e.code or 0)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    on_main_thread = threading.current_thread() is threading.main_thread()
    handlers = {signal.SIGINT: _end, signal.SIGALRM: _retry_held, **{s: _end for s in _ENDING_SIGNALS}}
    previous = {s: signal.signal(s, h) for s, h in handlers.items()} if on_main_thread else {}
    _HELD.clear()
    stdout = sys.stdout
    sys.stdout = _ReaderGoneStdout(stdout)
    try:
        from crossview.outputs import command_inputs

        with _saying_when_compiling(args.command), command_inputs(_command_inputs(args)):
            COMMANDS[args.command](args)
        sys.stdout.flush()
    except _Ended as e:
        print(f"crossview: ended by {signal.Signals(e.signum).name}; no partial output was kept", file=sys.stderr)
        return 128 + e.signum
    except KeyboardInterrupt:
        print("crossview: interrupted; no partial output was kept", file=sys.stderr)
        return EXIT_INTERRUPTED
    except (CrossviewError, OSError) as e:
        # Bad input: scenario, recording, dataset and config errors name the file and the key. Anything
        # else is a bug and shows its traceback.
        if args.verbose:
            raise
        message = str(e).splitlines()[0] if str(e) else type(e).__name__
        if isinstance(e, OSError) and e.filename:
            message = f"{e.filename}: {e.strerror}"
        print(f"crossview {args.command}: error: {message}", file=sys.stderr)
        return EXIT_BAD_INPUT
    finally:
        sys.stdout = stdout
        if on_main_thread:
            signal.setitimer(signal.ITIMER_REAL, 0)
        _HELD.clear()
        for ending, handler in previous.items():
            signal.signal(ending, handler)
    return 0


_THREAD_GRACE_S = 5.0  # how long `run` waits for threads that are no daemons before it ends without them


def run() -> None:
    """The `crossview` command. It ends when its command has: a thread that is no daemon and still runs
    `_THREAD_GRACE_S` later (a plug-in tracker's, left running) would keep the interpreter waiting on it for
    ever, so the process ends without waiting, after one warning line naming the threads (docs/plugins.md)."""
    status = main()
    # Threads of the command's own (a pool's result handler, say) end in moments: wait for them a little.
    deadline = time.monotonic() + _THREAD_GRACE_S
    for t in threading.enumerate():
        if t is not threading.main_thread() and not t.daemon:
            t.join(max(0.0, deadline - time.monotonic()))
    lingering = [t.name for t in threading.enumerate()
                 if t is not threading.main_thread() and not t.daemon and t.is_alive()]
    if lingering:
        print(f"crossview: warning: thread(s) {', '.join(map(repr, lingering))} still running when the command "
              "ended (a plug-in's, not a daemon); ending without them", file=sys.stderr)
        logging.shutdown()
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(status)  # (sys.exit would join them first: for ever)
    sys.exit(status)


if __name__ == "__main__":
    run()
