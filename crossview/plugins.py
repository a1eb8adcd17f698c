"""Which tracker a `--method` names, and the checks a plug-in tracker's output passes after every frame.

A method is one of the built-in names (`crossview`, `baseline`), a name an installed package registers under
the entry-point group `crossview.trackers`, or `package.module:Class`. The class is made as
``Class(cameras, config, skeleton)`` and fed frames through ``update(frame) -> targets``
(`tracker.protocol.PoseTracker`, docs/plugins.md). Bad names fail before any work with one line saying what
is missing; a plug-in that raises or reports a malformed target stops the run with one line naming the frame.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.metadata
import importlib.util
import inspect
import logging
import math
import numbers
import os
import sys
from dataclasses import dataclass

import numpy as np

from core.errors import CrossviewError, Interrupted
from core.types import Frame, Skeleton
from tracker.types import Target, TargetState, TrackerOutput

log = logging.getLogger(__name__)

BUILTIN_METHODS = {"crossview": "tracker.tracker:Tracker", "baseline": "tracker.baseline:BaselineTracker"}
ENTRY_POINT_GROUP = "crossview.trackers"


class PluginError(CrossviewError):
    """A `--method` that cannot be used, or a plug-in tracker that failed or reported malformed targets."""


@dataclass(frozen=True)
class Method:
    """A resolved `--method`.

    Attributes:
        spec: the name as given (written to the tracks file's header as its method).
        target: the `package.module:Class` it stands for.
        factory: the class, called as ``factory(cameras, config, skeleton)``.
        builtin: one of this project's trackers (trusted: their outputs are not re-checked).
    """

    spec: str
    target: str
    factory: type
    builtin: bool

    @property
    def source_files(self) -> tuple[str, ...]:
        """The files of the module the method names and of the module that defines its class, absolute (none
        for a built-in tracker, which the project's version covers, or a module with no file)."""
        if self.builtin:
            return ()
        names = (self.target.partition(":")[0], self.factory.__module__)
        files = (getattr(sys.modules.get(name), "__file__", None) for name in names)
        return tuple(dict.fromkeys(os.path.abspath(f) for f in files if f))

    def make(self, cameras, config, skeleton: Skeleton):
        """The tracker, made as ``factory(cameras, config, skeleton)``."""
        if self.builtin:
            return self.factory(cameras, config, skeleton)
        try:
            return self.factory(cameras, config, skeleton)
        except PLUGIN_FAILURES as exc:
            _reraise_interrupt(exc)
            raise PluginError(f"--method {self.spec}: {self.target}(cameras, config, skeleton) failed: "
                              f"{_exception_line(exc)}") from exc

    def update(self, tracker, frame: Frame, index: int):
        """`tracker.update(frame)`; a plug-in's exception becomes a PluginError naming the frame."""
        if self.builtin:
            return tracker.update(frame)
        try:
            return tracker.update(frame)
        except PLUGIN_FAILURES as exc:
            _reraise_interrupt(exc)
            raise PluginError(f"--method {self.spec}: {_frame_name(frame, index)}: update raised "
                              f"{_exception_line(exc)}") from exc

    def output(self, tracker, targets, frame: Frame, index: int, skeleton: Skeleton) -> TrackerOutput:
        """The TrackerOutput to record for this frame: the built-in tracker's `last_output`, or a plug-in's
        targets checked (`check_targets`) with its `last_output`'s detection assignments where it keeps one."""
        if self.builtin:
            return tracker.last_output
        where = f"--method {self.spec}: {_frame_name(frame, index)}"
        checked = check_targets(targets, frame.stamp_s, skeleton, where)
        assigned = np.full(frame.num_detections, -1, dtype=np.int64)
        last = getattr(tracker, "last_output", None)
        if last is not None:
            ids = np.asarray(getattr(last, "detection_target_ids", ()))
            if ids.shape != (frame.num_detections,) or not np.issubdtype(ids.dtype, np.integer):
                raise PluginError(f"{where}: last_output.detection_target_ids must be ({frame.num_detections},) "
                                  f"integers (one per detection, -1 unassigned), got {ids.dtype} {ids.shape}")
            assigned = ids.astype(np.int64)
        return TrackerOutput(stamp_s=frame.stamp_s, camera=frame.camera, targets=checked,
                             detection_target_ids=assigned)

    def reports_assignments(self, tracker) -> bool:
        """Whether the tracker says where each detection went (its `last_output`): association accuracy."""
        return self.builtin or hasattr(tracker, "last_output")


MAX_POSE_M = 1e6
"""Largest magnitude of a plug-in's joint coordinate, metres (as the tracker's other lengths are bounded, and far
inside float32, the tracks file's type)."""

PLUGIN_FAILURES = (Exception, SystemExit, KeyboardInterrupt)
"""What a plug-in's code may raise that is its failure: an error, and also `sys.exit` or a KeyboardInterrupt
it raises itself, which would otherwise end the command with the plug-in's status and no word."""


def _reraise_interrupt(exc: BaseException) -> None:
    """Lets the user's Ctrl-C (`core.errors.Interrupted`, raised by the command line wherever the command is,
    a plug-in's code included) end the command as Ctrl-C does."""
    if isinstance(exc, Interrupted):
        raise exc


def _frame_name(frame: Frame, index: int) -> str:
    return f"frame {index} (camera {frame.camera}, stamp {frame.stamp_s:.6f} s)"


def _exception_line(exc: BaseException) -> str:
    text = str(exc).splitlines()[0] if str(exc) else ""
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def check_targets(targets, stamp_s: float, skeleton: Skeleton, where: str) -> list[Target]:
    """A plug-in's targets as `Target`s after checking each (see tracker/protocol.py for the contract).

    Args:
        targets: what `update` returned: a sequence of objects with `id` and `pose` (`stamp_s`, `state` optional).
        stamp_s: the frame's stamp, the default `stamp_s` of a target.
        skeleton: the recording's joint layout; poses are (J, 3) with J = skeleton.num_joints.
        where: the method and frame, for the message.

    Raises:
        PluginError: the first malformed target, named by its position and id, with what was wrong.
    """
    if not isinstance(targets, list | tuple):
        raise PluginError(f"{where}: update returned a {type(targets).__name__}, expected a list of targets")
    J = skeleton.num_joints
    out = []
    seen: set[int] = set()
    for k, target in enumerate(targets):
        name = f"target {k}"
        if not hasattr(target, "id") or not hasattr(target, "pose"):
            raise PluginError(f"{where}: {name} is a {type(target).__name__} without `id` and `pose`")
        raw_id = target.id
        if isinstance(raw_id, (bool, np.bool_)) or not isinstance(raw_id, numbers.Integral):
            raise PluginError(f"{where}: {name} has id {raw_id!r} of type {type(raw_id).__name__}; ids must be ints")
        target_id = int(raw_id)
        if not -2**63 <= target_id < 2**63:  # (tracks files store ids as int64)
            raise PluginError(f"{where}: {name} has id {target_id}; ids must fit int64 ([-2^63, 2^63))")
        name = f"target {k} (id {target_id})"
        if target_id in seen:
            raise PluginError(f"{where}: {name}: the id is reported twice in one output")
        seen.add(target_id)
        try:
            pose = np.array(target.pose, dtype=np.float64)
        except (TypeError, ValueError):
            raise PluginError(f"{where}: {name}: pose is not numeric ({type(target.pose).__name__})") from None
        if pose.shape != (J, 3):
            raise PluginError(f"{where}: {name}: pose has shape {pose.shape}, expected ({J}, 3) for the "
                              f"{skeleton.name} skeleton of the recording")
        if np.isinf(pose).any():
            raise PluginError(f"{where}: {name}: pose holds infinite values")
        huge = np.abs(pose) > MAX_POSE_M  # (NaN compares False: a missing joint is checked below)
        if huge.any():
            raise PluginError(f"{where}: {name}: pose holds {float(pose[huge][0])!r} m; joints must be within "
                              f"{MAX_POSE_M:g} m (tracks files store float32, which holds 1e300 as infinity)")
        missing = np.isnan(pose)
        partial = missing.any(axis=1) & ~missing.all(axis=1)
        if partial.any():
            raise PluginError(f"{where}: {name}: joint {skeleton.joints[int(np.argmax(partial))]} is NaN in some "
                              "coordinates only (a missing joint is NaN in all three)")
        if missing.all():
            raise PluginError(f"{where}: {name}: pose is NaN in every joint")
        target_stamp = getattr(target, "stamp_s", stamp_s)
        if not isinstance(target_stamp, numbers.Real) or not math.isfinite(target_stamp):
            raise PluginError(f"{where}: {name}: stamp_s {target_stamp!r} is not a finite number of seconds")
        state = getattr(target, "state", TargetState.CONFIRMED)
        if not isinstance(state, TargetState):
            raise PluginError(f"{where}: {name}: state {state!r} is not a tracker.types.TargetState")
        out.append(Target(id=target_id, pose=pose, stamp_s=float(target_stamp), state=state))
    return out


def resolve(spec: str) -> Method:
    """The tracker class a `--method` names: a built-in name, an entry point of `crossview.trackers`, or
    `package.module:Class` (the module is imported from the installed packages, else from the current folder).

    Raises:
        PluginError: one line naming `spec` and what is missing (module, attribute, class, `update`).
    """
    if spec in BUILTIN_METHODS:
        return Method(spec, BUILTIN_METHODS[spec], _load_class(spec, BUILTIN_METHODS[spec]), builtin=True)
    if ":" in spec:
        return Method(spec, spec, _load_class(spec, spec), builtin=False)
    registered = {ep.name: ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}
    if spec in registered:
        return Method(spec, registered[spec].value, _load_class(spec, registered[spec].value), builtin=False)
    names = ", ".join(sorted(BUILTIN_METHODS) + sorted(registered))
    raise PluginError(f"--method {spec!r}: not a known tracker ({names}; more can be registered under the "
                      f"entry-point group {ENTRY_POINT_GROUP}) and not of the form package.module:Class")


def _load_class(spec: str, target: str) -> type:
    module_name, _, attr = target.partition(":")
    if not module_name or not attr:
        raise PluginError(f"--method {spec!r}: expected package.module:Class, with both parts")
    module = _import(spec, module_name)
    value = module
    for part in attr.split("."):
        if not hasattr(value, part):
            raise PluginError(f"--method {spec}: module {module_name} has no attribute {attr!r}")
        value = getattr(value, part)
    if not inspect.isclass(value):
        raise PluginError(f"--method {spec}: {attr} is a {type(value).__name__}, not a class "
                          "(expected a class made as Class(cameras, config, skeleton))")
    if not callable(getattr(value, "update", None)):
        raise PluginError(f"--method {spec}: class {attr} has no update(frame) method "
                          "(see docs/plugins.md for the tracker contract)")
    return value


def _import(spec: str, module_name: str):
    """Imports `module_name`; a top-level package that is not installed is looked for in the current folder,
    as `python -m` would, through importlib's path finder (sys.path is left as it is)."""
    top = module_name.partition(".")[0]
    try:
        if importlib.util.find_spec(top) is None:
            _import_from_current_folder(spec, top)
        return importlib.import_module(module_name)
    except PluginError:
        raise
    except PLUGIN_FAILURES as exc:
        _reraise_interrupt(exc)
        raise PluginError(f"--method {spec}: module {module_name} does not import ({_exception_line(exc)})") from exc


def _import_from_current_folder(spec: str, top: str) -> None:
    found = importlib.machinery.PathFinder.find_spec(top, [os.getcwd()])
    if found is None or found.loader is None:
        raise PluginError(f"--method {spec}: no module named {top!r} among the installed packages or in the "
                          f"current folder {os.getcwd()}")
    module = importlib.util.module_from_spec(found)
    sys.modules[top] = module
    try:
        found.loader.exec_module(module)
    except BaseException:
        del sys.modules[top]
        raise
    log.info("--method %s: %s imported from the current folder", spec, found.origin)
