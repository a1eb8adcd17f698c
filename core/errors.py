"""The project's errors: one base class that the command line turns into a one-line message and exit 2.

Each error names the file, key or value at fault and what would be valid. The readers of a file turn the
ValueError (or TypeError) of a check below them into one of these naming the file, once, at the file's
boundary: `sim.config.from_dict` (a dataclass's own check in `__post_init__`, or a key missing), and in
`crossview.formats.datasets` `image_size` and `load_cameras` (the calibration's checks in `core.calibration`)
and `convert` (a scene.json box, after `read_scene` checked the types). A ValueError that reaches the command
line unwrapped is a bug, and shows its traceback.
"""


class CrossviewError(ValueError):
    """Bad input to the project: a scenario, recording, dataset, result or configuration that cannot be used."""


class ConfigError(CrossviewError):
    """A tracker configuration (preset name or TOML file) that cannot be used."""


class ScenarioError(CrossviewError):
    """A scenario file that cannot be used; the message names the file and the key."""


class RecordingError(CrossviewError):
    """A file that cannot be read as the recording or tracks file asked for; the message names the file. The
    recording readers raise it where they find the damage (a corrupt record, message or header) and for the
    mcap library's documented exceptions; any other exception out of a reader is a bug."""


class Interrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) as the command line's signal handler raises it: told apart from a KeyboardInterrupt that
    code raises itself (a plug-in's, which is the plug-in's failure, not the user's Ctrl-C)."""


def one_line(error: BaseException) -> str:
    """An error's first line, for a one-line message (its class name when it says nothing)."""
    text = str(error).splitlines()[0] if str(error) else ""
    return text or type(error).__name__
