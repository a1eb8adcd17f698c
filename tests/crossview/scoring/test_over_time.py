"""score's warm-up (`from_s`), its per-person time line and its floor grid, against references made by hand and
against scoring the same inputs cut at the warm-up's end."""

import json

import numpy as np
import pytest

from core.records import PoseTruth
from crossview.scoring import ScoringError, default_from_s, score
from crossview.scoring.identity import body_roots
from tracker.types import Target, TrackerOutput

TEMPLATE = np.random.default_rng(5).normal(0.0, 0.2, (17, 3)) + [0.0, 0.0, 1.0]
START = {1: np.array([1.0, 1.0, 0.0]), 2: np.array([6.0, 3.0, 0.0])}
VELOCITY = {1: np.array([0.5, 0.0, 0.0]), 2: np.array([0.0, 0.4, 0.0])}  # m/s
DURATION_S = 8.0
AREA = (0.0, 0.0, 10.0, 8.0)  # m


def _pose(pid, t):
    return TEMPLATE + START[pid] + VELOCITY[pid] * t


def _truth():
    times = np.arange(int(DURATION_S * 100) + 1) / 100
    return [PoseTruth(t, np.array([1, 2]), np.stack([_pose(1, t), _pose(2, t)])) for t in times]


def _outputs(missing=lambda t: False, ghost=lambda t: False, ids=lambda t: (10, 20)):
    """Tracks that are the truth at 25 Hz, but without person 2 while `missing(t)`, with a ghost at (8, 7) m while
    `ghost(t)`, and person 1's and 2's target ids `ids(t)`."""
    outs = []
    for k in range(int(DURATION_S * 25) + 1):
        t = k / 25
        a, b = ids(t)
        targets = [Target(a, _pose(1, t), t)] + ([] if missing(t) else [Target(b, _pose(2, t), t)])
        if ghost(t):
            targets.append(Target(99, TEMPLATE + [8.0, 7.0, 0.0], t))
        outs.append(TrackerOutput(t, "cam0", targets, np.zeros(0, dtype=np.int64)))
    return outs


def _metrics(r):
    return (r.pcp, r.pcp_per_actor, r.mpjpe_mm, r.mota, r.idf1, r.id_switches, r.false_positives,
            r.false_negatives, r.hota, r.eval_instants, r.truth_person_instants)


def test_a_warm_up_scores_as_the_inputs_cut_at_its_end():
    """Leaving out the first 3 s scores what the truth and tracks from 3 s on score alone (the reference: the
    inputs cut there), and no longer counts the start-up misses."""
    truth, outs = _truth(), _outputs(missing=lambda t: t < 2.5, ghost=lambda t: 1.0 <= t < 5.0)
    whole = score(truth, outs, scored_area=AREA)
    late = score(truth, outs, scored_area=AREA, from_s=3.0)
    cut = score([s for s in truth if s.t_s >= 3.0 - 1e-9], [o for o in outs if o.stamp_s >= 3.0 - 1e-9],
                scored_area=AREA)
    assert _metrics(late) == _metrics(cut)
    # Person 2 untracked at the ticks 0.0 .. 2.5 s (the output of 2.48 s stands for the tick of 2.5 s).
    assert whole.false_negatives == 26 and late.false_negatives == 0
    assert late.false_positives == 20 and late.pcp == 1.0  # the ghost's ticks 3.0 .. 4.9 s
    assert (whole.from_s, late.from_s) == (0.0, 3.0)
    assert late.to_json(scenario=None, seed=None, num_cameras=None, num_people=None, duration_s=None)["from_s"] == 3.0
    # The warm-up's end may be the last instant; past it is an error that says how long the truth is.
    assert score(truth, outs, from_s=DURATION_S).eval_instants == 1
    with pytest.raises(ScoringError, match=r"--from 8\.5: the warm-up reaches past the end .* 8\.00 s"):
        score(truth, outs, from_s=8.5)


def test_the_time_line_and_the_floor_grid_hold_the_counted_misses_switches_and_false_positives():
    truth = _truth()
    outs = _outputs(missing=lambda t: 1.0 <= t < 3.0, ghost=lambda t: 6.0 <= t < 6.5,
                    ids=lambda t: (10, 20) if t < 5.0 else (20, 10))
    r = score(truth, outs, scored_area=AREA)
    people = r.timeline["people"]
    assert (r.timeline["start_s"], r.timeline["bin_s"], r.timeline["bins"]) == (0.0, 1.0, 9)  # 0 .. 8 s, 1 s bins
    # Person 2 is missed at the ten ticks of each of the seconds 1 and 2; the bin of 8 s holds one tick.
    assert people[2]["missed"] == [0, 10, 10, 0, 0, 0, 0, 0, 0]
    assert people[2]["matched"] == [10, 0, 0, 10, 10, 10, 10, 10, 1]
    assert people[1]["missed"] == [0] * 9
    assert people[2]["pcp"] == [1.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]
    assert sum(sum(p["missed"]) for p in people.values()) == r.false_negatives == 20
    # The swap at 5 s: one switch per person, at the place where each stood.
    assert r.id_switches == 2
    for pid in (1, 2):
        (switch,) = people[pid]["switches"]
        assert switch["t_s"] == 5.0 and switch["target_id"] == {1: 20, 2: 10}[pid]
        np.testing.assert_allclose([switch["x_m"], switch["y_m"]], body_roots(_pose(pid, 5.0)[None])[0])  # m
    # The floor grid: 1 m cells over the scored area; person 2 was missed from (6, 3.4) to (6, 4.2) m.
    floor = r.floor_grid
    assert (floor["origin_m"], floor["cell_m"], floor["shape"]) == ([0.0, 0.0], 1.0, [8, 10])
    misses = np.array(floor["misses"])
    assert misses.sum() == 20
    root = body_roots(TEMPLATE[None])[0]
    for t in np.arange(1.0, 3.0, 0.1):
        x, y = root + (START[2] + VELOCITY[2] * t)[:2]
        misses[int(y), int(x)] -= 1
    assert not misses.any()
    fp = np.array(floor["false_positives"])
    ghost = root + [8.0, 7.0]
    assert fp.sum() == r.false_positives == 6 and fp[int(ghost[1]), int(ghost[0])] == 6  # ticks 6.0 .. 6.5 s
    assert np.array(floor["id_switches"]).sum() == 2
    assert np.array(floor["truth"]).sum() == r.truth_person_instants


def test_the_default_warm_up_is_at_most_half_a_run():
    assert default_from_s(60.0) == default_from_s(120.0) > 0
    assert default_from_s(2.0) == 1.0


def test_score_from_and_map_on_the_command_line(store_recording, store_tracks, tmp_path, capsys):
    """`score --from 2 -o --map`: the JSON records the warm-up and holds the time line and floor grid, the map is a
    PNG; a warm-up past the end of the 6 s recording is one line, exit 2, nothing written."""
    from matplotlib.image import imread

    from crossview.cli import EXIT_BAD_INPUT, main

    out, picture = tmp_path / "s.json", tmp_path / "map.png"
    assert main(["--no-progress", "score", str(store_recording), str(store_tracks), "--from", "2", "-o", str(out),
                 "--map", str(picture)]) == 0
    assert "Scored from" in capsys.readouterr().out
    result = json.loads(out.read_text())
    assert result["from_s"] == 2.0 and result["timeline"]["start_s"] == pytest.approx(2.0, abs=0.01)
    assert sum(sum(row) for row in result["floor_grid"]["truth"]) == result["eval_instants"] * 4  # 4 people
    assert imread(picture).shape[2] in (3, 4)
    status = main(["--no-progress", "score", str(store_recording), str(store_tracks), "--from", "7", "-o",
                   str(tmp_path / "late.json"), "--map", str(tmp_path / "late.png")])
    err = capsys.readouterr().err.strip()
    assert status == EXIT_BAD_INPUT and len(err.splitlines()) == 1
    assert "--from 7: the warm-up reaches past the end of the recording, which holds 6.00 s of truth" in err
    assert not (tmp_path / "late.json").exists() and not (tmp_path / "late.png").exists()
