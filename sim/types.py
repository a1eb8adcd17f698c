"""What a person of the simulated crowd is doing (`Activity`); the plain data the simulation hands on
(truth, frames, store boxes) lives in `core.records`, where the formats and scoring read it too."""

from __future__ import annotations

import enum


class Activity(enum.IntEnum):
    """What a person is doing (also what the statistics count); `sim.crowd` decides it."""

    WALK = 0
    STAND = 1
    BROWSE = 2
    CHECKOUT = 3
