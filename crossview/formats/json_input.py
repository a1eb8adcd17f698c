"""Reading the JSON files users give (datasets, result files, OpenPose output) strictly, naming the file on
any problem."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

from core.errors import CrossviewError


class DatasetError(CrossviewError):
    """A dataset directory does not follow the published layout; the message names the file and the key."""


def check_input_file(path, error: type[CrossviewError] = CrossviewError) -> None:
    """Refuses an input that exists but is neither a regular file nor a folder (a FIFO, whose reader would wait
    for a writer forever; a device; a socket), naming it; a missing one is left to its reader to name.

    Raises:
        `error`: naming the path and what it is.
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return
    kind = ("a FIFO (named pipe)" if stat.S_ISFIFO(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a socket" if stat.S_ISSOCK(mode) else "not a regular file")
    raise error(f"{path}: is {kind}, not a regular file; give the file itself")


def read_json(path: Path, what: str = "") -> object:
    """A dataset or result JSON file, strictly: UTF-8, standard JSON (no NaN or Infinity).

    Raises:
        DatasetError: missing, unreadable, not UTF-8 or not valid JSON; the message names the file.
    """
    path = Path(path)
    check_input_file(path, DatasetError)
    if not path.is_file():
        raise DatasetError(f"{path}: {what or 'file'} not found (expected the crossview dataset layout: "
                           "calibration.json, detection.json or annotation_2d.json, optional annotation_3d.json)")
    return parse_json(read_text(path), path)


def read_text(path: Path, error: type[CrossviewError] = DatasetError) -> str:
    """The UTF-8 text of a file the user gave; `error` naming the file when it cannot be read or decoded."""
    try:
        return Path(path).read_bytes().decode("utf-8")
    except OSError as exc:
        raise error(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not UTF-8 text (byte {exc.start}); JSON files must be UTF-8") from None


def parse_json(text: str, path: Path, where: str = "", error: type[CrossviewError] = DatasetError) -> object:
    """Standard JSON (no NaN or Infinity) of `text` read from `path`; `error` naming the file and `where` (a
    prefix such as "line 3: ") when it is not."""

    def constant(name: str):
        raise error(f"{path}: {where}{name} is not a JSON number; write a finite number or leave the value out")

    try:
        return json.loads(text, parse_constant=constant)
    except json.JSONDecodeError as exc:
        raise error(f"{path}: {where}not valid JSON ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise error(f"{path}: {where}not valid JSON (nested too deeply)") from None


MAX_STAMP_S = 4e9
"""Largest timestamp a dataset may hold, seconds (a Unix time until 2096; stamps are stored as int64 ns)."""


def stamp_s(value, path: Path, where: str, camera_clock: bool = False) -> float:
    """A timestamp, seconds: a finite number in [0, MAX_STAMP_S], else a DatasetError naming `where`.

    With `camera_clock` (the stamp a camera put on its frame) [-MAX_STAMP_S, MAX_STAMP_S]: a camera's own clock
    may read before the recording's start (the simulated cameras' offsets and jitter do), and the tracker only
    takes differences of stamps.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DatasetError(f"{path}: {where}: timestamp {value!r} must be a number of seconds")
    low = -MAX_STAMP_S if camera_clock else 0
    if not low <= value <= MAX_STAMP_S:  # (NaN fails too)
        raise DatasetError(f"{path}: {where}: timestamp {value!r} must be in [{low:g}, {MAX_STAMP_S:g}] s")
    return float(value)
