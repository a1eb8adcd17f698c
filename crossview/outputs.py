"""Every output file of every command, written one way: checked before any work, then written under a
temporary name in its own folder, fsynced and renamed onto its name only when complete.

On any failure (an error, Ctrl-C or a terminating signal, a full disk) the temporary file is removed and
the folders made for the output are removed again, so nothing is left under a final name or beside it,
and the error names the output's path.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from core.errors import CrossviewError


class OutputError(CrossviewError):
    """An output that cannot be written: refused before any work, or failed while writing (e.g. a full
    disk); the message names the path.

    Attributes:
        errno: the file system's error number where writing failed (a full disk, the file-size limit, a
            permission): a failure of the environment, not of the input, that a rerun may not meet; None
            where the output was refused.
    """

    errno: int | None = None


_COMMAND_INPUTS: list[tuple] = [()]  # the running command's inputs (`command_inputs`), innermost last
_KEPT_TOGETHER: list[list[Path]] = []  # per `kept_together`, innermost last: the outputs committed inside and
# the folders made for them, in the order made


@contextlib.contextmanager
def command_inputs(paths):
    """Declares every input file of the running command (its scenario and the files that names, its config,
    plug-in module, recordings, result and dataset files) for its duration: every output checked or written
    meanwhile (`check_output`, `AtomicOutput`) is refused when it is one of them, whichever part of the
    command writes it. The command line declares them once per command (`crossview.cli`)."""
    _COMMAND_INPUTS.append(tuple(paths))
    try:
        yield
    finally:
        _COMMAND_INPUTS.pop()


@contextlib.contextmanager
def kept_together(folder):
    """Outputs written inside are kept only all together: on any exception (an error, Ctrl-C or a terminating
    signal) every output committed meanwhile is removed again, with the folders made for them, and so are
    `folder` and the folders above it that did not exist on entry (each only when empty). For a command whose
    step writes a file that a later step may fail after (`compare`'s tracks of one tracker, then another's
    failure): nothing is kept, as it says."""
    folder = Path(folder)
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    _KEPT_TOGETHER.append([])
    try:
        yield
    except BaseException:
        for path in reversed(_KEPT_TOGETHER[-1]):  # each file, then the folders made for it, innermost first
            with contextlib.suppress(OSError):  # (a folder that is not empty: something else was put there)
                path.rmdir() if path.is_dir() else path.unlink()
        for made in missing:
            with contextlib.suppress(OSError):
                made.rmdir()
        raise
    finally:
        done = _KEPT_TOGETHER.pop()
        if _KEPT_TOGETHER:  # an enclosing group answers for them too
            _KEPT_TOGETHER[-1].extend(done)


def same_file(a, b) -> bool:
    """Whether paths `a` and `b` name one file: the same path once every symlink is resolved, or, both
    existing, the same inode on the same device (a hard link)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        sa, sb = os.stat(a), os.stat(b)
    except (OSError, ValueError):
        return False
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def check_output(path, inputs: tuple = ()) -> None:
    """Fails early, before any work, when `path` cannot be written.

    That is when writing it would replace one of `inputs` or of the running command's declared inputs
    (`command_inputs`): the same file under any name, through a symlink or a hard link (`same_file`);
    something that is not a regular file (a device, a pipe) or a folder; or when its folder neither exists
    nor can be made (a file stands in the way, or the nearest existing folder is not writable). Nothing is
    created here: the folders are made when the output is written (`AtomicOutput`).

    Args:
        path: the output file.
        inputs: the command's input files (None entries are skipped).

    Raises:
        OutputError: naming the path and what would be valid.
    """
    path = Path(path)
    for given in (*inputs, *_COMMAND_INPUTS[-1]):
        if given is not None and same_file(given, path):
            raise OutputError(f"{path}: is also an input ({given}); writing it would destroy the input, "
                              "so choose another output")
    if path.is_dir():
        raise OutputError(f"{path}: is a folder; give a file name for the output")
    if path.exists() and not path.is_file():
        raise OutputError(f"{path}: is not a regular file (a device or a pipe); choose a file name for the output")
    folder = path.parent
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"{folder}: output folder cannot be created ({existing} is a file, not a folder)")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"{folder}: output folder is not writable ({existing}); choose another output")


class AtomicOutput:
    """One output file written atomically: a binary file-like object (`write`, `tell`, `flush`).

    The folders the output needs are made on opening; the data go to `.NAME.PID.tmp` beside the output;
    `commit` flushes, fsyncs and renames it onto `path` (and fsyncs the folder); `abort` removes it and
    the folders made for it. As a context manager: commit on a clean exit, abort on any exception
    (KeyboardInterrupt and signals included). A failure of the file system while writing (a full disk)
    is an `OutputError` naming `path`, raised after the temporary file is gone.

    Args:
        path: the output file.
        inputs: the command's input files, which the output must not be (see `check_output`).
    """

    def __init__(self, path, inputs: tuple = ()):
        self.path = Path(path)
        check_output(self.path, inputs)
        self.tmp = temporary_name(self.path)
        remove_dead_temporaries(self.path)
        self._made: list[Path] = []  # folders made for this output, outermost first
        self._file = None
        self._done = False
        with self._aborting():
            missing = []
            folder = self.path.parent
            while not folder.exists():
                missing.append(folder)
                folder = folder.parent
            for folder in reversed(missing):
                folder.mkdir()
                self._made.append(folder)
            self._file = open(self.tmp, "wb")

    @contextlib.contextmanager
    def _aborting(self):
        """Aborts on any exception; an OSError (a full disk) becomes an `OutputError` naming the output."""
        try:
            yield
        except OSError as e:
            self.abort()
            error = OutputError(f"{self.path}: cannot be written ({e.strerror or e}); nothing was kept")
            error.errno = e.errno
            raise error from None
        except BaseException:
            self.abort()
            raise

    def write(self, data) -> int:
        """Appends `data` (bytes)."""
        with self._aborting():
            return self._file.write(data)

    def tell(self) -> int:
        return self._file.tell()

    def flush(self) -> None:
        with self._aborting():
            self._file.flush()

    def commit(self) -> None:
        """Makes the output appear under its name, complete and on disk; a no-op once committed or aborted."""
        if self._done:
            return
        with self._aborting():
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            os.replace(self.tmp, self.path)
        self._done = True
        if _KEPT_TOGETHER:
            _KEPT_TOGETHER[-1].extend([*self._made, self.path])
        _fsync_folder(self.path.parent)

    def abort(self) -> None:
        """Removes the temporary file and the folders made for the output; never raises an OSError (the
        file system's failure that led here is what gets reported). A no-op once committed or aborted."""
        if self._done:
            return
        self._done = True
        if self._file is not None:
            try:
                self._file.close()  # (its flush fails again on a full disk; the descriptor is closed anyway)
            except OSError:
                pass
        try:
            os.unlink(self.tmp)
        except OSError:
            pass
        for folder in reversed(self._made):
            try:
                folder.rmdir()
            except OSError:  # something else was put there meanwhile
                break

    def __enter__(self) -> AtomicOutput:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.abort()


def temporary_name(path) -> Path:
    """Where this process writes `path` until it is complete: `.NAME.PID.tmp` beside it."""
    path = Path(path)
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def remove_dead_temporaries(path) -> list[Path]:
    """Removes the temporary files (or folders) of `path` (`temporary_name`) that an earlier run left, one
    killed with SIGKILL that could remove nothing: only those of this pattern whose process no longer exists
    (a live writer's, another user's included, are left alone). Returns those removed."""
    import shutil

    path = Path(path)
    prefix = f".{path.name}."
    try:
        entries = os.listdir(path.parent)
    except OSError:
        return []
    removed = []
    for entry in entries:
        pid = entry[len(prefix):-len(".tmp")] if entry.startswith(prefix) and entry.endswith(".tmp") else ""
        if not pid.isdigit() or int(pid) == os.getpid() or process_alive(int(pid)):
            continue
        stale = path.parent / entry
        try:
            if stale.is_dir() and not stale.is_symlink():
                shutil.rmtree(stale)
            else:
                stale.unlink()
        except OSError:
            continue
        removed.append(stale)
    return removed


def process_alive(pid: int) -> bool:
    """Whether a process `pid` exists (one of another user's included)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _fsync_folder(folder: Path) -> None:
    """Makes a rename in `folder` durable (where the system allows opening a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_bytes(data: bytes, path, inputs: tuple = ()) -> None:
    """Writes `data` to `path` atomically (`AtomicOutput`)."""
    with AtomicOutput(path, inputs) as out:
        out.write(data)
