"""Named child random generators: one scenario seed, one independent stream per subsystem."""

from __future__ import annotations

import zlib

import numpy as np


def child_rng(seed: int, name: str) -> np.random.Generator:
    """The generator of subsystem `name` (for example "crowd", "cameras", "clock", "detector").

    Streams depend only on the seed and the name, so adding a camera does not change how people walk.
    """
    return np.random.default_rng([seed, zlib.crc32(name.encode())])
