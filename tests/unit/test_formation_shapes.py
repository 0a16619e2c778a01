"""Formation geometry, hierarchy, master choice and Table 3."""

from __future__ import annotations

import math
from itertools import combinations

import pytest

from petswarm.controllers.formation_shapes import (
    Mode,
    Shape,
    choose_master,
    depth_toward_user,
    hierarchy_levels,
    master_target_distance,
    mode_change,
    neighbours,
    slots,
)


def test_column_trails_the_master() -> None:
    assert slots(Shape.COLUMN, 4, 1.0) == [(0.0, 0.0), (-1.0, 0.0), (-2.0, 0.0), (-3.0, 0.0)]


def test_line_alternates_sides_with_the_master_in_the_middle() -> None:
    ys = [y for _, y in slots("line", 5, 0.8)]
    assert ys == pytest.approx([0, 0.8, -0.8, 1.6, -1.6])
    assert all(x == 0 for x, _ in slots("line", 5, 0.8))


def test_wedge_arms_open_backward_and_keep_the_spacing() -> None:
    wedge = slots(Shape.WEDGE, 5, 1.0)
    assert all(x < 0 for x, _ in wedge[1:])
    assert wedge[1][1] > 0 > wedge[2][1]
    for member in range(1, 5):
        (ahead,) = neighbours(Shape.WEDGE, member)
        assert math.dist(wedge[member], wedge[ahead]) == pytest.approx(1.0)


@pytest.mark.parametrize("shape", list(Shape))
def test_no_two_slots_nearer_than_the_spacing(shape: Shape) -> None:
    for a, b in combinations(slots(shape, 7, 0.9), 2):
        assert math.dist(a, b) >= 0.9 - 1e-9


def test_neighbours_per_shape() -> None:
    assert [neighbours(Shape.COLUMN, k) for k in range(4)] == [[], [0], [1], [2]]
    assert [neighbours(Shape.WEDGE, k) for k in range(5)] == [[], [0], [0], [1], [2]]
    assert [neighbours(Shape.LINE, k) for k in range(5)] == [[], [0], [0], [1], [2]]


def test_bad_shape_inputs_are_refused() -> None:
    with pytest.raises(ValueError):
        slots("star", 3, 1.0)
    with pytest.raises(ValueError, match="spacing"):
        slots(Shape.LINE, 3, 0.0)
    with pytest.raises(ValueError, match="members"):
        slots(Shape.LINE, 0, 1.0)


def test_depth_and_master_target_distance() -> None:
    column = slots(Shape.COLUMN, 4, 1.0)
    assert depth_toward_user(column, "behind") == pytest.approx(3.0)
    assert depth_toward_user(column, "ahead") == 0.0
    assert master_target_distance(Mode.FOLLOWING, column) == pytest.approx(1.0)
    assert master_target_distance(Mode.LEADING, column) == pytest.approx(4.0)
    assert master_target_distance(Mode.LEADING, slots(Shape.LINE, 4, 1.0)) == pytest.approx(1.0)
    assert master_target_distance(Mode.LEADING, slots(Shape.WEDGE, 4, 1.0)) == pytest.approx(1 + math.sqrt(2))


def test_hierarchy_levels_count_from_the_farthest() -> None:
    assert hierarchy_levels({0: 1.0, 1: 2.0, 2: 4.0, 3: 3.0}) == {2: 1, 3: 2, 1: 3, 0: 4}
    assert hierarchy_levels({5: 2.0, 3: 2.0}) == {3: 1, 5: 2}


def test_master_is_closest_when_following_and_farthest_when_leading() -> None:
    distances = {0: 2.5, 1: 1.0, 2: 3.5, 3: 1.9}
    assert choose_master(Mode.FOLLOWING, distances) == 1
    assert choose_master(Mode.LEADING, distances) == 2
    with pytest.raises(ValueError):
        choose_master(Mode.LEADING, {})


# Table 3 on a column of four: following, user 1 m ahead of the master; the user turns about.
COLUMN = slots(Shape.COLUMN, 4, 1.0)
MEMBERS = [0, 1, 2, 3]
FOLLOWING_DISTANCES = {0: 1.0, 1: 2.0, 2: 3.0, 3: 4.0}


def test_table3_following_to_leading_with_change() -> None:
    change = mode_change(Mode.FOLLOWING, Mode.LEADING, True, MEMBERS, FOLLOWING_DISTANCES, COLUMN)
    assert change.new_master == 3
    assert not change.mirrored
    # every robot stays where it is: the old master is now the farthest back, nearest the user
    assert change.slots_by_member == {3: (0, 0), 2: (-1, 0), 1: (-2, 0), 0: (-3, 0)}
    assert master_target_distance(Mode.LEADING, change.slots_by_member, change.new_master) == pytest.approx(4.0)


def test_table3_following_to_leading_without_change() -> None:
    change = mode_change(Mode.FOLLOWING, Mode.LEADING, False, MEMBERS, FOLLOWING_DISTANCES, COLUMN)
    assert change.new_master == 0
    assert change.mirrored
    # the slaves go round to the master's other side: again trailing it along the new direction
    assert change.slots_by_member == {0: (0, 0), 1: (-1, 0), 2: (-2, 0), 3: (-3, 0)}


def test_table3_leading_to_following_with_change() -> None:
    # leading, the master (3) is 4 m ahead of the user; the old master 0 trails, 1 m from the user
    leading_slots = {3: (0.0, 0.0), 2: (-1.0, 0.0), 1: (-2.0, 0.0), 0: (-3.0, 0.0)}
    change = mode_change(Mode.LEADING, Mode.FOLLOWING, True, MEMBERS, FOLLOWING_DISTANCES, leading_slots, master=3)
    assert change.new_master == 0
    assert change.slots_by_member == {0: (0, 0), 1: (-1, 0), 2: (-2, 0), 3: (-3, 0)}
    assert not change.mirrored


def test_table3_leading_to_following_without_change_on_a_wedge() -> None:
    wedge = slots(Shape.WEDGE, 3, 1.0)
    distances = {0: 2.4, 1: 1.0, 2: 1.0}
    change = mode_change("leading", "following", False, [0, 1, 2], distances, wedge)
    assert change.new_master == 0
    assert change.mirrored
    # the left arm (member 1) is on the right after the turn-about, and stays behind the master
    (x1, y1), (_x2, y2) = change.slots_by_member[1], change.slots_by_member[2]
    assert x1 == pytest.approx(wedge[1][0]) and x1 < 0
    assert y1 == pytest.approx(-wedge[1][1]) and y1 < 0 < y2


def test_table3_with_change_keeps_every_robot_in_place_on_a_wedge() -> None:
    wedge = slots(Shape.WEDGE, 5, 1.0)
    distances = {k: 1.0 - x for k, (x, _) in enumerate(wedge)}
    change = mode_change("following", "leading", True, list(range(5)), distances, wedge)
    assert change.new_master == 3
    for a, b in combinations(range(5), 2):
        assert math.dist(change.slots_by_member[a], change.slots_by_member[b]) == pytest.approx(
            math.dist(wedge[a], wedge[b])
        )


def test_mode_change_needs_a_slot_and_a_distance_for_every_member() -> None:
    with pytest.raises(ValueError, match="members"):
        mode_change("following", "leading", True, [0, 1, 7], FOLLOWING_DISTANCES, COLUMN)


def test_kept_slots_turn_the_places_into_the_new_masters_frame_and_the_chain_follows_distance() -> None:
    from petswarm.controllers.formation_shapes import handover_chain, kept_slots

    column = dict(zip((11, 12, 13), slots("column", 3, 0.6), strict=True))  # robot 11 leads, 13 at the tail
    kept = kept_slots(column, 13)
    assert kept[13] == (0.0, 0.0) and kept[12] == pytest.approx((-0.6, 0.0)) and kept[11] == pytest.approx((-1.2, 0.0))
    assert handover_chain(kept, 13) == (13, 12, 11)  # reversed: the column's own slot list describes it again
    wedge = dict(enumerate(slots("wedge", 3, 0.6)))
    kept = kept_slots(wedge, 1)
    assert kept[2] == pytest.approx((0.0, 2 * 0.6 * math.sin(math.radians(45))))  # the other arm, beside it
    assert handover_chain(kept, 1) == (1, 0, 2)
    with pytest.raises(ValueError, match="new master"):
        kept_slots(wedge, 7)
