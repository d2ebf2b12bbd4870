"""The why rules: the causes (a)-(d) and the one-line summary, fixed before any why run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fnnbook.why import Axis, AuthorsCheck, Why, WhyGrid, causes, read_whys, summary, write_whys

NOISE = Axis("noise_std", (0.001, 0.003, 0.01, 0.03), "the noise level of Fig. 4g is not given", ours=0.01)
STATED = Axis("N", (10, 20), "the horizon the paper states", paper=20, ours=20)


def grid(holds, axes=(NOISE,), n=5) -> WhyGrid:
    return WhyGrid(axes=tuple(axes), holds=np.asarray(holds, bool), n=n, rule="the claim's rule holds")


def letters(**kw) -> str:
    return "".join(c.letter for c in causes(**kw))


def test_the_profile_point_is_read_at_each_axis_ours_and_across_an_axis_without_one() -> None:
    assert grid([False, False, True, False]).holds_at_profile() is True  # noise 0.01: index 2
    assert grid([True, True, False, True]).holds_at_profile() is False
    levels = Axis("level", (-1, 0, 1), "the levels (stated)", paper=(-1, 0, 1))  # no ours: every level
    two = grid(np.array([[True, True], [True, False], [True, True]]), axes=(levels, STATED))
    assert two.holds_at_profile() is False  # at N = 20, level 0 fails
    off = Axis("beta", (0.1, 0.2), "the decay is not given", ours=0.3)
    assert grid([True, True], axes=(off,)).holds_at_profile() is None


def test_a_threshold_along_an_open_axis_reads_as_a_range_and_cause_b() -> None:
    g = grid([True, True, False, False])
    assert summary([g]) == "holds for noise_std <= 0.003, fails at 0.01 and above (5 seeds per point)"
    assert letters(grids=[g]) == "b"


def test_a_setting_the_paper_states_is_not_an_open_setting() -> None:
    g = grid([True, False], axes=(STATED,))
    assert letters(grids=[g]) == ""  # mixed, but along the stated horizon: no (b)


def test_never_holding_is_d_unless_the_authors_networks_reproduce_it() -> None:
    g = grid([False] * 4)
    assert letters(grids=[g]) == "d"
    theirs = AuthorsCheck(verdict="reproduced", ours="not reproduced", checks={"x": True}, networks="theirs")
    assert letters(grids=[g], authors=theirs) == "c"
    same = AuthorsCheck(verdict="not reproduced", ours="not reproduced", checks={"x": False}, networks="theirs")
    assert letters(grids=[g], authors=same) == "d"


def test_differing_readings_are_a_and_equal_ones_are_not() -> None:
    g = grid([True] * 4)
    assert letters(grids=[g], readings={"strict": "partly", "as worded": "reproduced"}) == "a"
    assert letters(grids=[g], readings={"strict": "partly", "as worded": "partly"}) == ""


def test_a_two_axis_grid_names_the_slice_through_the_profile_point() -> None:
    beta = Axis("beta", (0.0, 0.02), "the decay rate is not given", ours=0.02)
    g = grid([[True, True], [True, True], [False, True], [False, False]], axes=(NOISE, beta))
    line = summary([g])
    assert line.startswith("holds at 5 of 8 points (noise_std x beta)")
    assert "at beta = 0.02 (ours): holds for noise_std <= 0.01, fails at 0.03 and above" in line


def test_a_two_axis_grid_reports_every_slice_not_only_the_profile_point() -> None:
    # the residual levels hold at every gain but the profile's: the line must say so for each gain
    level = Axis("level", tuple(range(12)), "the 12 residual levels (stated)", paper=tuple(range(12)))
    gain = Axis("L", (5.0, 10.0, 20.0), "the gain L is not given", ours=20.0)
    holds = np.ones((12, 3), bool)
    holds[8:, 2] = False
    line = summary([grid(holds, axes=(level, gain))])
    assert "at L = 5: holds at all 12 level values" in line
    assert "at L = 10: holds at all 12 level values" in line
    assert "at L = 20 (ours): holds for level <= 7, fails at 8 and above" in line
    # every slice failing reads as such too: no slice is left out
    holds[:, 0] = False
    line = summary([grid(holds, axes=(level, gain))])
    assert "at L = 5: fails at all 12 level values" in line and "at L = 10: holds at all 12" in line


def test_infeasible_points_are_excluded_from_every_count_and_the_line_says_why() -> None:
    bound = Axis("u_max", (4.0, 5.0, 6.0), "the thrust bound", paper=4.0, ours=6.0)
    gamma = Axis("Gamma", (2.0, 8.0), "the adaptation gain is not stated", ours=8.0)
    holds = np.array([[True, True], [True, False], [False, True]])  # 4 of 6 points, 1 of 2 feasible ones
    feasible = np.array([[False, False], [False, False], [True, True]])
    why = "below the 5.53 N per motor the vehicle needs at the reference's peak"
    g = WhyGrid(axes=(bound, gamma), holds=holds, n=5, rule="r", feasible=feasible, infeasible=why)
    line = summary([g])
    assert line.startswith("holds at 1 of 2 feasible points (u_max x Gamma; 4 points excluded: " + why + ")")
    assert "4 of 6" not in line
    # the excluded points never count: holding only where infeasible is (d); the causes count feasible points
    never = WhyGrid(axes=(bound, gamma), holds=~feasible, n=5, rule="r", feasible=feasible, infeasible=why)
    assert letters(grids=[never]) == "d"
    found = causes(grids=[g])
    assert [c.letter for c in found] == ["b"] and "holds at 1 of 2 feasible points" in found[0].evidence
    # a grid mixed only through its excluded points is not mixed
    flat = WhyGrid(axes=(bound, gamma), holds=np.array([[True, False], [False, True], [True, True]]), n=5,
                   rule="r", feasible=feasible, infeasible=why)
    assert not flat.mixed and letters(grids=[flat]) == ""
    back = WhyGrid.from_json(json.loads(json.dumps(g.to_json())))
    assert summary([back]) == line
    with pytest.raises(ValueError, match="why"):
        WhyGrid(axes=(bound, gamma), holds=holds, n=5, rule="r", feasible=feasible)
    with pytest.raises(ValueError, match="feasible point"):
        WhyGrid(axes=(bound, gamma), holds=holds, n=5, rule="r", feasible=np.zeros((3, 2), bool), infeasible=why)
    with pytest.raises(ValueError, match="shape"):
        WhyGrid(axes=(bound, gamma), holds=holds, n=5, rule="r", feasible=np.ones(3, bool), infeasible=why)


def test_shapes_values_and_runs_are_checked() -> None:
    with pytest.raises(ValueError, match="shape"):
        grid([True, False])
    with pytest.raises(ValueError, match="booleans"):
        WhyGrid(axes=(NOISE,), holds=np.zeros(4), n=5, rule="r")
    with pytest.raises(ValueError, match="twice"):
        Axis("x", (1, 1), "s")
    with pytest.raises(ValueError, match="not prose"):
        Why("S3", "partly")


def test_round_trip_and_a_tampered_cause_is_refused(tmp_path) -> None:
    w = Why("S3", "partly", grids=(grid([True, True, False, False]),), readings={"strict": "partly"})
    path = write_whys(tmp_path, [w])
    back = read_whys(path)["S3"]
    assert back.summary == w.summary and back.causes == w.causes
    data = json.loads(path.read_text())
    data["whys"][0]["causes"] = [["c", "made up"]]
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="stored causes differ"):
        read_whys(path)


def test_several_grids_are_named_and_the_unit_is_the_grids_own() -> None:
    a = WhyGrid(axes=(NOISE,), holds=np.array([True] * 4), n=5, rule="r", title="as written", unit="unit")
    b = WhyGrid(axes=(NOISE,), holds=np.array([False] * 4), n=1, rule="r", title="as flown", unit="network")
    line = summary([a, b])
    assert line.startswith("as written: holds at every noise_std (0.001, 0.003, 0.01, 0.03) (5 units per point)")
    assert "; as flown: fails at every noise_std (0.001, 0.003, 0.01, 0.03) (1 network per point)" in line
    assert summary([a]).startswith("holds at every")  # one grid: no name


WINDOW = Axis("window", ("whole record", "after settling"), "the window Fig. 5b's accuracy is scored over",
              ours="whole record", kind="reading")
DECAY = Axis("beta", (0.0, 0.1), "the cascade's decay in Sec. 4 is not stated", ours=0.0, kind="usage")


def test_d_stands_only_when_every_reading_and_usage_fails_with_ours_and_the_authors() -> None:
    never = grid([False] * 4)
    # another grid of ours holds at a reading point: no (d), and the reading axis that decides it is (a)
    by_window = grid([[False, True]] * 4, axes=(NOISE, WINDOW))
    assert letters(grids=[never, by_window]) == "a"
    # a usage point where it holds (the decayed cascade): no (d)
    by_decay = grid([False, True], axes=(DECAY,))
    assert "d" not in letters(grids=[never, by_decay])
    # the authors' networks hold under some reading: no (d)
    theirs = WhyGrid(axes=(WINDOW,), holds=np.array([False, True]), n=1, rule="r", unit="network",
                     networks="authors")
    assert "d" not in letters(grids=[never, theirs])
    # a reading of the paper-profile result holds: no (d)
    assert "d" not in letters(grids=[never], readings={"strict": "partly", "as worded": "reproduced"})
    # every reading, usage and setting fails, ours and the authors': (d), naming the kinds tried
    all_fail = grid([[False, False]] * 4, axes=(NOISE, WINDOW))
    theirs_fail = WhyGrid(axes=(WINDOW,), holds=np.array([False, False]), n=1, rule="r", unit="network",
                          networks="authors")
    same = AuthorsCheck(verdict="not reproduced", ours="not reproduced", checks={"x": False}, networks="theirs")
    found = causes(grids=[all_fail, theirs_fail], authors=same)
    assert [c.letter for c in found] == ["d"]
    assert "reading" in found[0].evidence and "nor with the authors' networks" in found[0].evidence


def test_an_authors_grid_mixed_on_an_open_setting_is_not_b_and_kinds_round_trip() -> None:
    theirs = WhyGrid(axes=(NOISE,), holds=np.array([True, False, False, False]), n=1, rule="r",
                     networks="authors")
    assert "b" not in letters(grids=[theirs])
    g = grid([[False, True]] * 4, axes=(NOISE, WINDOW))
    back = WhyGrid.from_json(json.loads(json.dumps(g.to_json())))
    assert back.axes[1].kind == "reading" and back.networks == "ours"
    with pytest.raises(ValueError, match="kind"):
        Axis("x", (1, 2), "s", kind="guess")
