"""The sweep report's statistics over seeds and its plots' axes, without running cells; and the warm-up of the
cells' plan."""

import math

import pytest

from crossview.experiments import sweep, sweep_report
from crossview.scoring import default_from_s

# Student's t, two-sided 95 %, from a printed table (NIST/SEMATECH e-Handbook, 1.3.6.7.2): 2 and 4 degrees of
# freedom.
T_975 = {2: 4.303, 4: 2.776}


def _row(cameras: int, seed: int, pcp: float, idf1: float = 1.0, status: str = "ok") -> dict:
    score = {"pcp": pcp, "idf1": idf1, "mota": 0.9, "from_s": 5.0} if status == "ok" else None
    return {"values": [["cameras", cameras]], "seed": seed, "status": status, "score": score, "label": f"c{cameras}",
            "method": "crossview", "preset": "store"}


WANTED = {"scenario": "store_layout2", "axes": [{"key": "cameras", "values": [12, 20, 30]}], "seeds": [0, 1, 2],
          "methods": ["crossview"], "presets": ["store"], "duration_s": 30.0}


def test_the_interval_over_seeds_is_students_t():
    values = [0.90, 0.93, 0.95]
    mean = sum(values) / 3
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / 2)
    low, high = sweep_report.t_interval(values)
    assert (low + high) / 2 == pytest.approx(mean)
    assert (high - low) / 2 == pytest.approx(T_975[2] * sd / math.sqrt(3), rel=1e-3)
    five = [1.0, 2.0, 3.0, 4.0, 5.0]
    assert sweep_report.t_interval(five)[1] - 3.0 == pytest.approx(T_975[4] * math.sqrt(2.5) / math.sqrt(5), rel=1e-3)
    assert sweep_report.t_interval([0.7]) == (0.7, 0.7)  # one seed: no spread to speak of


def test_means_and_report_give_each_points_mean_and_interval_and_leave_failed_cells_out():
    rows = [_row(12, s, p) for s, p in zip((0, 1, 2), (0.90, 0.91, 0.92))]
    rows += [_row(20, 0, 0.95), _row(20, 1, 0.97), _row(20, 2, None, status="CrossviewError: boom")]
    rows += [_row(30, s, 0.96) for s in (0, 1, 2)]
    means = sweep_report.means(WANTED, rows)
    assert [(m["cameras"], m["cells"], m["ok"]) for m in means] == [(12, 3, 3), (20, 3, 2), (30, 3, 3)]
    low, high = sweep_report.t_interval([0.90, 0.91, 0.92])
    assert means[0]["pcp"] == {"mean": pytest.approx(0.91), "ci95": [low, high], "n": 3}
    assert means[1]["pcp"]["n"] == 2 and means[1]["hota"] is None
    assert all("tracker_fps" not in m for m in means)  # (speeds vary from run to run: not in results.json)
    report = sweep_report.report_markdown(WANTED | {"version": "x"}, rows, [])
    assert f"| all | 12 | 3/3 | 0.910 ({low:.3f}–{high:.3f}) |" in report
    assert "scored from 5 s on" in report
    assert "meets PCP >= 0.95 and IDF1 >= 0.9 from cameras = 20" in report


def test_an_axis_of_integers_gets_integer_ticks():
    rows = [_row(c, s, 0.9 + 0.001 * c) for c in (12, 20, 30) for s in (0, 1)]
    ax = sweep_report.figure(WANTED, rows, "pcp", "PCP", 0.95).axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["12", "20", "30"]
    many = {**WANTED, "axes": [{"key": "cameras", "values": list(range(4, 44, 2))}]}
    rows = [_row(c, 0, 0.9) for c in range(4, 44, 2)]
    ax = sweep_report.figure(many, rows, "pcp", "PCP", 0.95).axes[0]
    ticks = [t for t in ax.get_xticks() if 4 <= t <= 42]
    assert ticks and all(float(t).is_integer() for t in ticks)


def test_cells_leave_out_the_default_warm_up_or_the_given_one_and_a_longer_one_is_refused():
    axes = (sweep.parse_axis("duration_s", "2,30"),)
    cells = sweep.plan(sweep.SweepSpec("store_layout1", axes=axes, warm_up_s=None))
    assert [c.from_s for c in cells] == [default_from_s(2.0), default_from_s(30.0)] == [1.0, 5.0]
    given = sweep.plan(sweep.SweepSpec("store_layout1", axes=axes, warm_up_s=1.5))
    none = sweep.plan(sweep.SweepSpec("store_layout1", axes=axes))
    assert [c.from_s for c in given] == [1.5, 1.5] and [c.from_s for c in none] == [0.0, 0.0]
    # Another warm-up is another score: another key (none keeps the key a cell had before warm-ups).
    assert len({c.key for c in cells + given + none}) == 6
    with pytest.raises(sweep.CrossviewError, match=r"--from 3: the warm-up reaches past the end of the cells, "
                                                   r"which simulate 2 s"):
        sweep.plan(sweep.SweepSpec("store_layout1", axes=axes, warm_up_s=3.0))


def test_a_folder_from_before_warm_ups_is_the_same_sweep_as_one_scored_from_0():
    old = {"format": 1, "version": "v", "scenario": "s", "axes": [{"key": "cameras"}], "duration_s": 10.0,
           "scenario_resolved_sha256": "x"}
    assert sweep._identity(old) == sweep._identity({**old, "warm_up_s": 0.0})
    assert sweep._identity(old) != sweep._identity({**old, "warm_up_s": None})  # (the default rule: 5 s here)
