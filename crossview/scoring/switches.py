"""The identity switches of a zoned tracks file by place and cause (issue 47, docs/zones.md "Switches by place").

A zoned run (`crossview track --zones`) reports each target from the zone whose cell holds its body root
(`tracker.zones.Zone.owns`), under a global id the merger gave it (`tracker.handover`). For each ID switch that
py-motmetrics counts (`IdentityAccumulator.events`: a person matched to another target than at their previous
match), this module says where it happened and why:

- where: the person's root at the switch, whether it lies inside an overlap (inside the widened regions of two
  zones or more) and its distance to the nearest border line between two cells;
- why, from the zones that reported the old target at the person's previous match and the new one now:
  - `zone tracker`: one zone reported both: that zone's own tracker changed the person's id (lost and
    re-born, or swapped with someone near);
  - `hand-over: new id`: another zone reports the person now, under a global id nobody was matched to before:
    the merger did not match the zone's new target to the person the other zone held (outside the gate, or
    the other zone had stopped reporting them);
  - `hand-over: another person's id`: another zone reports the person now, under a global id another person
    was matched to before: the merger matched the new target to the wrong one;
  - `hand-over: back to an earlier id`: another zone reports the person now, under a global id this person
    alone had before.

Pure: the scorer's per-update comparisons in, the list out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from crossview.scoring.identity import IdEvent
from tracker.zones import Zone, owner

TRACKER = "zone tracker"
NEW_ID = "hand-over: new id"
ANOTHERS_ID = "hand-over: another person's id"
EARLIER_ID = "hand-over: back to an earlier id"
WHYS = (TRACKER, NEW_ID, ANOTHERS_ID, EARLIER_ID)


@dataclass(frozen=True)
class PlacedSwitch:
    """One ID switch: when (s), who, from which target to which, where the person stood (m), the zones that
    reported the old and the new target (-1: off every cell), inside an overlap or not, the distance to the
    nearest border line (m; None with one zone) and why (`WHYS`)."""

    t_s: float
    person_id: int
    from_target: int
    to_target: int
    x_m: float
    y_m: float
    from_zone: int
    to_zone: int
    in_overlap: bool
    border_m: float | None
    why: str

    def to_json(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def zones_of(summary_zones: Sequence[dict]) -> list[Zone] | None:
    """The zones a zoned tracks file's summary lists (`"zones"`: each its `cell` and `region`); None for a file
    whose summary lists none, or lists them without their regions (made before regions were written)."""
    if not summary_zones or any("region" not in z for z in summary_zones):
        return None
    x1 = max(z["cell"][2] for z in summary_zones)
    y1 = max(z["cell"][3] for z in summary_zones)
    return [Zone(k, tuple(map(float, z["cell"])), tuple(map(float, z["region"])), (),
                 (z["cell"][2] >= x1, z["cell"][3] >= y1)) for k, z in enumerate(summary_zones)]


def _borders(zones: Sequence[Zone]) -> tuple[list[float], list[float]]:
    """The border lines between cells: x = const and y = const (the cells' edges inside the floor)."""
    x0, y0 = min(z.cell[0] for z in zones), min(z.cell[1] for z in zones)
    xs = sorted({z.cell[0] for z in zones if z.cell[0] > x0})
    ys = sorted({z.cell[1] for z in zones if z.cell[1] > y0})
    return xs, ys


def place(events: Sequence[IdEvent], at_s: Sequence[float], truth: Sequence[tuple[np.ndarray, np.ndarray]],
          targets: Sequence[tuple[np.ndarray, np.ndarray]], zones: Sequence[Zone]) -> list[PlacedSwitch]:
    """Every switch of `events` by place and cause (module docstring).

    Args:
        events: py-motmetrics' events in update order (`IdentityAccumulator.events`).
        at_s: per update, the compared instant (the tracker output's stamp), seconds.
        truth: per update, the people's ids (G,) and floor roots (G, 2+).
        targets: per update, the targets' ids (H,) and floor roots (H, 2+).
        zones: the run's zones.
    """
    xs, ys = _borders(zones)
    last: dict[int, tuple[int, int]] = {}  # person -> (update, target) of their latest match
    matched_by: dict[int, set[int]] = {}  # target -> persons matched to it so far
    out = []

    def root_of(update: int, ids_roots, wanted: int) -> np.ndarray:
        ids, roots = ids_roots[update]
        return np.asarray(roots, dtype=np.float64)[list(np.asarray(ids).tolist()).index(wanted), :2]

    for e in events:
        if e.kind not in ("MATCH", "SWITCH"):
            continue
        if e.kind == "SWITCH" and e.person_id in last:
            before, old = last[e.person_id]
            xy = root_of(e.update, truth, e.person_id)
            from_zone = int(owner(zones, root_of(before, targets, old)[None])[0])
            to_zone = int(owner(zones, root_of(e.update, targets, e.target_id)[None])[0])
            others = matched_by.get(e.target_id, set()) - {e.person_id}
            if from_zone == to_zone:
                why = TRACKER
            elif others:
                why = ANOTHERS_ID
            elif e.target_id in matched_by:
                why = EARLIER_ID
            else:
                why = NEW_ID
            inside = sum(bool(_in_box(z.region, xy)) for z in zones)
            distances = [abs(xy[0] - x) for x in xs] + [abs(xy[1] - y) for y in ys]
            out.append(PlacedSwitch(float(at_s[e.update]), int(e.person_id), int(old), int(e.target_id),
                                    float(xy[0]), float(xy[1]), from_zone, to_zone, inside >= 2,
                                    float(min(distances)) if distances else None, why))
        last[e.person_id] = (e.update, e.target_id)
        matched_by.setdefault(e.target_id, set()).add(e.person_id)
    return out


def _in_box(box, xy) -> bool:
    x0, y0, x1, y1 = box
    return x0 <= xy[0] <= x1 and y0 <= xy[1] <= y1


def summary_lines(switches: Sequence[PlacedSwitch]) -> list[str]:
    """The switches as text lines for `crossview score`: counts by cause and place, then one line each."""
    lines = [f"Switches by place ({len(switches)}; zoned run)"]
    for why in WHYS:
        picked = [s for s in switches if s.why == why]
        if picked:
            inside = sum(s.in_overlap for s in picked)
            lines.append(f"  {why}: {len(picked)} ({inside} in an overlap)")
    for s in switches:
        border = "-" if s.border_m is None else f"{s.border_m:.2f} m"
        lines.append(f"  {s.t_s:8.2f} s  person {s.person_id:>4}  at ({s.x_m:5.1f}, {s.y_m:5.1f}) m  border {border:>7}"
                     f"  {'overlap' if s.in_overlap else 'inside '}  zone {s.from_zone} -> {s.to_zone}  {s.why}")
    return lines
