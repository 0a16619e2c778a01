"""The improved surround law (petswarm/controllers/surround_improved.py), its selection, and the surround figures
and snapshot instants drawn from world lines (petswarm/lab/surround_metrics.py, surround_plots.py)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import pytest

from petswarm.controllers.surround import SurroundConfig, SurroundController
from petswarm.controllers.surround_improved import ImprovedSurroundController
from petswarm.controllers.surround_pilot import SurroundDriverConfig, SurroundPilot
from petswarm.lab.surround_metrics import contacts, obstacle_pass, surround_metrics
from petswarm.lab.surround_plots import is_surround_run, snapshot_instants
from petswarm.scenario import _surround

IMPROVED = SurroundConfig(law="improved")
DT = 0.04


def test_the_law_is_named_and_checked_and_the_paper_stays_the_default() -> None:
    assert SurroundConfig().law == "paper"
    with pytest.raises(ValueError, match="law must be one of"):
        SurroundConfig(law="better")
    with pytest.raises(ValueError, match="brake_mps2"):
        SurroundConfig(law="improved", brake_mps2=0.0)
    assert SurroundConfig.from_dict(IMPROVED.to_dict()) == IMPROVED
    assert _surround({"enabled": True, "law": "improved"})["law"] == "improved"
    with pytest.raises(ValueError, match="law"):
        _surround({"enabled": True, "law": 3})


def test_the_pilot_runs_the_law_its_config_names() -> None:
    assert type(SurroundPilot(SurroundDriverConfig()).controller) is SurroundController
    assert type(SurroundPilot(SurroundDriverConfig(law=IMPROVED)).controller) is ImprovedSurroundController


def test_a_lone_robot_beside_a_walking_human_takes_up_his_pace() -> None:
    """Velocity match: the paper's law has only the rear's surround force to move a robot level with him. Without
    the walking lane, whose share of the lead for a robot level with him moves it on ahead (tested below)."""
    improved = ImprovedSurroundController(SurroundConfig(law="improved", lane_gain=0.0))
    velocity = (0.0, 0.0)
    for _ in range(50):  # 2 s; the human walks at 1 m/s along x, 0.5 m to the robot's left
        velocity = improved.step_plain([], [], (0.0, 0.5), velocity, DT, human_velocity=(1.0, 0.0))
    assert velocity[0] == pytest.approx(1.0, abs=0.15)
    paper = SurroundController(SurroundConfig())
    still = (0.0, 0.0)
    for _ in range(50):
        still = paper.step_plain([], [], (0.0, 0.5), still, DT)
    assert abs(still[0]) < 0.05  # level with him, c_i gives no push along his walk


def test_a_robot_the_human_left_behind_is_pulled_to_him_harder_than_one_beside_him() -> None:
    far, near = ImprovedSurroundController(IMPROVED), ImprovedSurroundController(IMPROVED)
    v_far = far.step_plain([], [], (2.0, 0.0), (0.0, 0.0), DT, human_velocity=(0.0, 0.0))
    v_near = near.step_plain([], [], (0.85, 0.0), (0.0, 0.0), DT, human_velocity=(0.0, 0.0))
    assert v_far[0] > v_near[0] > 0
    assert abs(v_far[1]) < 1e-12


def test_closing_on_an_obstacle_point_repels_harder_than_standing_off_it() -> None:
    wall = [(0.45, 0.0)]
    closing, still = ImprovedSurroundController(IMPROVED), ImprovedSurroundController(IMPROVED)
    v_closing = closing.step_plain([], wall, None, (1.0, 0.0), DT)
    v_still = still.step_plain([], wall, None, (0.0, 0.0), DT)
    # 0.45 m off: within A either way, but the braking distance of 1 m/s brings the wall much nearer
    assert closing.last_forces[1][0] < 10 * still.last_forces[1][0] < 0
    assert v_closing[0] < 1.0 and v_still[0] < 0.0


def test_a_human_walking_into_a_robot_held_in_front_of_him_pushes_it_off() -> None:
    ahead, beside = ImprovedSurroundController(IMPROVED), ImprovedSurroundController(IMPROVED)
    # the robot stands 0.7 m ahead of him (he is behind it, at -x), he comes at 1 m/s
    pushed = ahead.step_plain([], [], (-0.7, 0.0), (0.0, 0.0), DT, human_velocity=(1.0, 0.0))
    calm = beside.step_plain([], [], (-0.7, 0.0), (0.0, 0.0), DT, human_velocity=(0.0, 0.0))
    assert pushed[0] > calm[0]


def test_a_neighbour_closing_from_behind_is_repelled_by_its_tracked_speed() -> None:
    fast, slow = ImprovedSurroundController(IMPROVED), ImprovedSurroundController(IMPROVED)
    behind = [(-0.45, 0.0)]
    v_fast = fast.step_plain(behind, [], None, (0.0, 0.0), DT, neighbour_velocities=[(1.0, 0.0)])
    v_slow = slow.step_plain(behind, [], None, (0.0, 0.0), DT, neighbour_velocities=[(0.0, 0.0)])
    assert v_fast[0] > v_slow[0]


def test_a_robot_closing_on_a_slower_neighbour_ahead_is_held_to_what_still_stops_behind_it() -> None:
    """The stopping rule: the forces alone (velocity match toward 1 m/s, the pull) drive it on into him."""
    rule = ImprovedSurroundController(IMPROVED)
    ahead = [(0.3, 0.0)]  # 0.1 m of gap, the neighbour going at 0.3 m/s
    v = rule.step_plain(
        ahead, [], (1.5, 0.0), (1.0, 0.0), DT, human_velocity=(1.0, 0.0), neighbour_velocities=[(0.3, 0.0)]
    )
    c = IMPROVED
    away = 0.3 - c.brake_mps2 * c.track_lag_s
    gap = 0.3 - 2 * c.robot_radius_m - c.stop_margin_m
    assert v[0] == pytest.approx(math.sqrt(away**2 + 2 * c.brake_mps2 * gap))
    assert v[0] < 0.6
    # the same neighbour off to the side (not on the way) does not hold it back
    free = ImprovedSurroundController(IMPROVED)
    side = free.step_plain(
        [(0.0, 0.6)], [], (1.5, 0.0), (1.0, 0.0), DT, human_velocity=(1.0, 0.0), neighbour_velocities=[(0.3, 0.0)]
    )
    assert side[0] > 0.9


def test_a_robot_just_ahead_of_the_walking_human_keeps_out_of_his_way() -> None:
    rule = ImprovedSurroundController(IMPROVED)
    # he is 0.45 m behind it (0.05 m short of his clearance plus its radius and the margin) at 1 m/s
    v = rule.step_plain([], [], (-0.45, 0.0), (0.5, 0.0), DT, human_velocity=(1.0, 0.0))
    c = IMPROVED
    gap = max(0.0, 0.45 - c.human_clearance_m - c.robot_radius_m - c.human_margin_m)
    assert v[0] >= 1.0 + c.brake_mps2 * c.track_lag_s - math.sqrt(2 * c.escape_mps2 * gap) - 1e-9


def test_a_robot_between_the_walking_human_and_a_slower_robot_ahead_yields_to_him_first() -> None:
    """No velocity keeps both stop rules: his comes first (the robot ahead yields in turn to one coming at it)."""
    c = IMPROVED
    rule = ImprovedSurroundController(IMPROVED)
    ahead, slow = [(0.22, 0.0)], [(0.5, 0.0)]  # 2 cm of gap, at half his pace
    v = rule.step_plain(ahead, [], (-0.44, 0.0), (0.8, 0.0), DT, human_velocity=(1.0, 0.0), neighbour_velocities=slow)
    gap = max(0.0, 0.44 - c.human_clearance_m - c.robot_radius_m - c.human_margin_m)
    assert v[0] >= 1.0 + c.brake_mps2 * c.track_lag_s - math.sqrt(2 * c.escape_mps2 * gap) - 1e-9


def _state(t: float, bodies: list[dict[str, Any]], collisions: int, obstacles: list | None = None) -> dict:
    return {"t_us": round(t * 1e6), "bodies": bodies, "collisions": collisions, "obstacles": obstacles or []}


def _robot(name: str, x: float, y: float) -> dict[str, Any]:
    return {
        "id": name,
        "kind": "robot",
        "x": x,
        "y": y,
        "yaw": 0.0,
        "vx": 0.0,
        "vy": 0.0,
        "radius": 0.1,
        "ir": "beacon",
    }


def _user(x: float, vx: float) -> dict[str, Any]:
    return {"id": "user", "kind": "user", "x": x, "y": 0.0, "yaw": 0.0, "vx": vx, "vy": 0.0, "radius": 0.25}


def test_new_contacts_are_put_down_to_the_pairs_touching_when_the_count_rose() -> None:
    wall = [{"kind": "wall", "x0": 0.0, "y0": 1.0, "x1": 5.0, "y1": 1.0}]
    world = [
        _state(0.02, [_robot("robot-1", 0, -1), _robot("robot-2", 1, -1), _user(3, 0)], 0, wall),
        # robot-1 touches robot-2 (0.2 m apart), robot-3 the wall, robot-4 the human: three new contacts
        _state(
            0.04,
            [
                _robot("robot-1", 0.8, -1),
                _robot("robot-2", 1.0, -1),
                _robot("robot-3", 2.0, 0.9),
                _robot("robot-4", 3.35, 0.0),
                _user(3, 0),
            ],
            3,
            wall,
        ),
        _state(0.06, [_robot("robot-1", 0, -1), _user(3, 0)], 4, wall),  # one nobody can be blamed for
    ]
    assert contacts(world) == {
        "robot_robot": 1,
        "robot_obstacle": 1,
        "robot_human": 1,
        "unattributed": 1,
        "total": 4,
    }


def _walk() -> list[dict[str, Any]]:
    """A human standing 2 s, then walking along x at 1 m/s past a cylinder (x 4..6) to x 8, then standing to
    11 s; two robots 0.5 m behind him, abreast."""
    cylinder = [{"kind": "circle", "x": 5.0, "y": 2.0, "r": 1.0}]
    world = []
    for k in range(1, 551):
        t = k * 0.02
        x = min(max(t - 2.0, 0.0), 8.0)
        robots = [_robot("robot-1", x - 0.5, 0.3), _robot("robot-2", x - 0.5, -0.3)]
        world.append(_state(t, [*robots, _user(x, 1.0 if 2.0 < t < 10.0 else 0.0)], 0, cylinder))
    return world


def test_the_figures_of_a_walk_past_an_obstacle() -> None:
    figures = surround_metrics(_walk())
    assert figures["contacts"]["total"] == 0
    assert figures["connected_fraction"] == 1.0
    assert figures["centre_to_human_walking_m"]["median"] == pytest.approx(0.5, abs=1e-3)
    assert figures["ahead_while_walking"] == 0.0
    assert figures["r_end_m"] == pytest.approx(0.3)
    passing = obstacle_pass(_walk())
    assert passing["human_reached_s"] == pytest.approx(6.0, abs=0.03)
    assert passing["human_past_s"] == pytest.approx(8.02, abs=0.03)
    assert passing["swarm_past_s"] == pytest.approx(8.52, abs=0.03)
    assert passing["time_to_pass_s"] == pytest.approx(2.52, abs=0.03)
    assert passing["lag_s"] == pytest.approx(0.5, abs=0.03)


def test_snapshots_show_the_gathered_swarm_the_walk_and_the_end() -> None:
    world = _walk()
    instants = snapshot_instants(world, 6)
    times = [world[i]["t_us"] / 1e6 for i in instants]
    assert len(instants) == 6 and times[-1] == pytest.approx(11.0)
    assert times == sorted(times) and all(not math.isnan(t) for t in times)
    assert is_surround_run(world)
    assert not is_surround_run([_state(0.02, [{**_robot("robot-1", 0, 0), "ir": "idle"}, _user(0, 0)], 0)])


def _ring_along(world_xy: list[tuple[float, float]]) -> list[tuple[list[float], tuple[float, float]]]:
    """The ring's noise-free ranges of a robot (heading 0, radius 0.1) at each of ``world_xy`` beside the corridor's
    wall (x 4..7, y -0.6), with the velocity that takes it from each position to the next in one step."""
    from radio_hub.physics.world import World, WorldConfig, parse_obstacle

    world = World(
        WorldConfig(robot_radius_m=0.1), [parse_obstacle({"kind": "wall", "x0": 4, "y0": -0.6, "x1": 7, "y1": -0.6})]
    )
    world.add("r", "robot", *world_xy[0], 0.0)
    out = []
    for (x, y), (nx, ny) in zip(world_xy, [*world_xy[1:], world_xy[-1]], strict=True):
        world.place("r", x, y, 0.0)
        out.append((world.ultrasonic("r").tolist(), ((nx - x) / DT, (ny - y) / DT)))
    return out


def _cones() -> tuple[list[float], list[float]]:
    angles = [math.radians(a) for a in (0.0, 45.0, 90.0, 135.0, 180.0, -135.0, -90.0, -45.0)]
    return [math.cos(a) for a in angles], [math.sin(a) for a in angles]


def test_a_wall_end_that_slid_into_a_blind_gap_is_remembered_where_it_was_heard() -> None:
    """The echo memory (beyond the paper): a robot sliding past a wall's end at 0.5 m/s hears it on its front cone,
    then the end crosses the 15 degree gap to the next cone, where the ring hears nothing of it; the memory still
    has a point within a few cm of it, and the law's wall rule holds the robot's speed toward it."""
    from petswarm.controllers.surround_memory import EchoMemory

    memory, cos, sin = EchoMemory(), *_cones()
    path = [(3.5 + 0.02 * k, -0.54) for k in range(20)]  # 0.5 m/s along y = -0.54, its flank over the wall's line
    end = (4.0, -0.6)
    in_gap = 0
    for (x, y), (ranges, velocity) in zip(path, _ring_along(path), strict=True):
        points = memory.step(ranges, cos, sin, [False] * 8, velocity, DT, 0.1)
        bearing = math.degrees(math.atan2(end[1] - y, end[0] - x))
        if -30 < bearing < -16:  # the end in the blind gap between the cones at 0 and -45 degrees
            in_gap += 1
            # the ring does not hear the end: at most the wall beyond it, where the front cone's edge meets it
            assert all(not r < math.dist((x, y), end) - 0.1 + 0.01 for r in ranges)
            assert min(math.dist(p, (end[0] - x, end[1] - y)) for p in points) < 0.035
            law = ImprovedSurroundController(IMPROVED)
            held = law.step_plain([], [], None, (0.6, 0.0), DT, walls=points)
            free = ImprovedSurroundController(IMPROVED).step_plain([], [], None, (0.6, 0.0), DT)
            toward = (end[0] - x, end[1] - y)
            unit = (toward[0] / math.hypot(*toward), toward[1] / math.hypot(*toward))
            assert held[0] * unit[0] + held[1] * unit[1] < free[0] * unit[0] + free[1] * unit[1] - 0.05
    assert in_gap >= 3


def test_the_memory_forgets_a_point_a_beam_sees_past_or_that_a_beacon_explains_or_too_old() -> None:
    from petswarm.controllers.surround_memory import MEMORY_S, EchoMemory

    cos, sin = _cones()
    nothing = [math.nan] * 8
    ahead = [0.2, *[math.nan] * 7]  # a wall 0.3 m ahead of the centre, on the front cone
    memory = EchoMemory()
    memory.step(ahead, cos, sin, [False] * 8, (0.0, 0.0), DT, 0.1)
    assert len(memory.points) == 5  # its arc, across the cone
    # the front cone now hears nothing: the arc's points inside its beam are not there; its edge points may be
    left = memory.step(nothing, cos, sin, [False] * 8, (0.0, 0.0), DT, 0.1)
    assert 0 < len(left) <= 2 and all(abs(math.degrees(math.atan2(y, x))) > 13 for x, y in left)
    # heard past by a neighbour's echo farther off: carved too; nearer (hiding it): kept
    hidden = EchoMemory()
    hidden.step(ahead, cos, sin, [False] * 8, (0.0, 0.0), DT, 0.1)
    assert len(hidden.step([0.1, *[math.nan] * 7], cos, sin, [True, *[False] * 7], (0.0, 0.0), DT, 0.1)) == 5
    # an echo a beacon explains is not remembered
    body = EchoMemory()
    body.step(ahead, cos, sin, [True, *[False] * 7], (0.0, 0.0), DT, 0.1)
    assert body.points == []
    # too old: gone, even unseen (behind a neighbour all along)
    old = EchoMemory()
    old.step(ahead, cos, sin, [False] * 8, (0.0, 0.0), DT, 0.1)
    steps = round(MEMORY_S / DT) + 1
    for _ in range(steps):
        kept = old.step([0.1, *[math.nan] * 7], cos, sin, [True, *[False] * 7], (0.0, 0.0), DT, 0.1)
    assert kept == []


def test_the_wall_rule_lets_a_robot_slide_past_a_wall_point_but_not_drive_into_it() -> None:
    from petswarm.controllers.surround_improved import WALL_BRAKE_MPS2, WALL_LATE_S, WALL_MARGIN_M

    c = IMPROVED
    point = [(0.25, 0.0)]  # 0.15 m from its skin, straight ahead
    into = ImprovedSurroundController(IMPROVED).step_plain([], [], None, (1.0, 0.0), DT, walls=point)
    gap = 0.25 - c.robot_radius_m - WALL_MARGIN_M
    a, late = WALL_BRAKE_MPS2, WALL_LATE_S
    limit = math.sqrt(a * a * late * late + 2 * a * gap) - a * late
    assert into[0] == pytest.approx(limit) and limit * late + limit**2 / (2 * a) == pytest.approx(gap)
    past = ImprovedSurroundController(IMPROVED).step_plain([], [], None, (0.0, 1.0), DT, walls=point)
    assert past[1] > 0.9


def test_a_wall_beside_a_robot_leaves_no_remembered_point_nearer_than_itself() -> None:
    """The arcs' edge points: a cone hearing a wall beside the robot puts its arc's edges off the wall, nearer
    than it; each fresh arc replaces them, so a robot standing or driving along a wall is not held back."""
    from petswarm.controllers.surround_memory import EchoMemory

    cos, sin = _cones()
    path = [(5.0 + 0.004 * k, -0.4) for k in range(8)]  # 0.1 m/s along the wall, 0.1 m off it
    memory = EchoMemory()
    for ranges, velocity in _ring_along(path):
        points = memory.step(ranges, cos, sin, [False] * 8, velocity, DT, 0.1)
    assert points and all(y <= -0.2 + 0.01 for _, y in points)  # none off the wall, toward the robot's path
    law = ImprovedSurroundController(IMPROVED)
    assert law.step_plain([], [], None, (1.0, 0.0), DT, walls=points)[0] > 0.95


def test_the_walking_lane_draws_a_robot_to_his_line_while_he_walks_and_lets_go_once_he_stops() -> None:
    """The walking lane (docs/SURROUND.md, item 12): while the human walks, a robot further than the lane's half-width
    from his line (his tracked position along his tracked velocity) is drawn back in and may not move further out;
    inside the lane, or once he has stood still for the lane's ramp, the law is as without it."""
    lane = SurroundConfig(law="improved", lane_gain=4.0, lane_rate=3.0, lane_half_m=0.2, lane_out_m=0.0)
    off = SurroundConfig(law="improved", lane_gain=0.0, lane_rate=0.0)
    walking, standing = (1.0, 0.0), (0.0, 0.0)

    def commands(
        config: SurroundConfig,
        he: tuple[float, float],
        his: list[tuple[float, float]],
        velocity: tuple[float, float] = (1.0, 0.0),
    ) -> list[tuple[float, float]]:
        law = ImprovedSurroundController(config)
        return [law.step_plain([], [], he, velocity, DT, human_velocity=v) for v in his]

    # 0.6 m to his right (he is at +y), walking level with him: drawn in toward his line, harder once the lane is
    # in (its ramp, 1 s)
    drawn = commands(lane, (0.0, 0.6), [walking] * 40)
    free = commands(off, (0.0, 0.6), [walking] * 40)
    assert drawn[-1][1] > free[-1][1] + 0.05
    assert drawn[-1][1] - free[-1][1] > drawn[5][1] - free[5][1] + 0.03
    # moving further out (-y) it is held to no speed outward; without the lane it keeps going out
    outward = (1.0, -0.3)
    assert commands(lane, (0.0, 0.9), [walking] * 40, outward)[-1][1] >= -1e-9
    assert commands(off, (0.0, 0.9), [walking] * 40, outward)[-1][1] < -0.1
    # behind him near his line, well inside the lane: nothing changes
    assert commands(lane, (0.9, 0.05), [walking] * 40) == commands(off, (0.9, 0.05), [walking] * 40)
    # he stops: the lane goes out over its ramp, then the law is as without it
    stopped = [walking] * 40 + [standing] * 30
    assert commands(lane, (0.0, 0.9), stopped)[-1] == commands(off, (0.0, 0.9), stopped)[-1]
    assert commands(lane, (0.0, 0.9), stopped, outward)[-1] == commands(off, (0.0, 0.9), stopped, outward)[-1]
    # standing all along, the lane never came in
    assert commands(lane, (0.0, 0.9), [standing] * 40) == commands(off, (0.0, 0.9), [standing] * 40)


def test_with_an_outer_lane_a_robot_past_halfway_to_it_is_pushed_out_to_it_not_drawn_in() -> None:
    """``lane_out_m``: while he walks no robot stays between the two lanes (where a corridor's wall would meet it)."""
    outer = SurroundConfig(law="improved", lane_gain=4.0, lane_rate=3.0, lane_half_m=0.4, lane_out_m=0.8)
    off = SurroundConfig(law="improved", lane_gain=0.0)
    walking = [(1.0, 0.0)] * 40

    def last(config: SurroundConfig, he: tuple[float, float], velocity: tuple[float, float]) -> tuple[float, float]:
        law = ImprovedSurroundController(config)
        return [law.step_plain([], [], he, velocity, DT, human_velocity=v) for v in walking][-1]

    # 0.7 m to his right (past halfway, 0.6 m): pushed further out (-y), and free to move out
    assert last(outer, (0.0, 0.7), (1.0, 0.0))[1] < last(off, (0.0, 0.7), (1.0, 0.0))[1] - 0.01
    assert last(outer, (0.0, 0.7), (1.0, -0.3))[1] < -0.1
    # 0.55 m to his right (short of halfway): drawn in, and held to no speed outward
    assert last(outer, (0.0, 0.55), (1.0, 0.0))[1] > last(off, (0.0, 0.55), (1.0, 0.0))[1] + 0.01
    assert last(outer, (0.0, 0.55), (1.0, -0.3))[1] >= -1e-9


def test_the_centring_stiffens_while_the_human_stands_still_and_eases_off_once_he_walks() -> None:
    """``still_centring``: the swarm's extent at rest is the repulsion against the springs, above r* with
    ``centring`` alone; once he has stopped (his track slower than ``still_speed_mps`` after he walked) the spring
    toward him is stiffer by it, ramped in and out over ``still_ramp_s``."""
    still = SurroundConfig(law="improved", still_centring=2.0, still_ramp_s=0.4)
    off = SurroundConfig(law="improved", still_centring=0.0)

    def pulls(config: SurroundConfig, his: list[tuple[float, float]]) -> list[float]:
        law = ImprovedSurroundController(config)
        return [law.step_plain([], [], (0.7, 0.0), (0.0, 0.0), DT, human_velocity=v)[0] for v in his]

    standing, walking = [(0.0, 0.0)] * 20, [(1.0, 0.0)] * 20
    # 0.7 m from him, he has walked and stopped: pulled in harder once the ramp is in, by 2.0 * 0.7 m/s^2 over a step
    stopped = pulls(still, walking + standing)
    assert stopped[-1] == pytest.approx(pulls(off, walking + standing)[-1] + 2.0 * 0.7 * DT)
    assert stopped[20] < stopped[-1]
    # before he first walks, and while he walks, the law is as without it
    assert pulls(still, standing + walking) == pulls(off, standing + walking)
    # he walks on again: as without it once the ramp is out
    assert pulls(still, walking + standing + walking)[-1] == pulls(off, walking + standing + walking)[-1]


def test_the_safety_stage_takes_an_echo_off_a_tracked_neighbour_to_move_at_its_tracked_speed() -> None:
    """``safety_tracked``: a neighbour new to a cone has no range rate yet, and the ring took it to stand still; a
    robot following it at its pace 7 cm behind was slowed to 0.12 m/s. With the neighbour's track the echo moves
    away at its tracked speed (less ``brake_mps2`` times ``track_lag_s``)."""
    from types import SimpleNamespace

    import numpy as np

    from petswarm.controllers.pet_controller import SafetyStage
    from petswarm.controllers.surround_pilot import SAFETY_IMPROVED
    from radio_hub.values import OwnSensors

    angles = np.radians(np.arange(8) * 45.0)
    ranges = np.full(8, math.nan)
    ranges[0] = 0.07  # the neighbour's surface, 7 cm ahead
    sensors = OwnSensors(1_000_000, ranges, angles, 0.0, (0.9, 0.0, 0.0))
    tracked = SurroundDriverConfig(law=SurroundConfig(law="improved", safety_tracked=1.0))
    pilot = SurroundPilot(tracked)
    neighbour = SimpleNamespace(names=["robot-2"], positions=np.array([[0.28, 0.0]]), velocities=np.array([[0.9, 0.0]]))
    pilot.tracker = neighbour  # type: ignore[assignment]
    receding = pilot._tracked_receding(sensors, ())
    assert receding[0] == pytest.approx(0.9 - 1.5 * 0.1)
    assert receding[1:] == (0.0,) * 7
    stage = SafetyStage(SAFETY_IMPROVED)
    assert stage.translation(0.9, 0.0, angles.tolist(), ranges.tolist(), receding)[0] == pytest.approx(0.87)
    assert stage.translation(0.9, 0.0, angles.tolist(), ranges.tolist(), ())[0] == pytest.approx(0.12)
    # an echo no tracked body explains (a wall) keeps the ring's own rate
    pilot.tracker = SimpleNamespace(  # type: ignore[assignment]
        names=["robot-2"], positions=np.array([[0.6, 0.3]]), velocities=np.array([[0.9, 0.0]])
    )
    assert pilot._tracked_receding(sensors, ()) == (0.0,) * 8
    # nor one 6 cm in front of the neighbour's surface (a wall's end beside it), though within its match
    pilot.tracker = SimpleNamespace(  # type: ignore[assignment]
        names=["robot-2"], positions=np.array([[0.33, 0.0]]), velocities=np.array([[0.9, 0.0]])
    )
    assert pilot._tracked_receding(sensors, ()) == (0.0,) * 8


def test_a_robot_level_with_the_walking_human_in_the_outer_lane_keeps_less_of_the_lead() -> None:
    """``lane_outer_level_lead``: past halfway to the outer lane and level with him, a robot aims less far ahead of
    him (it links the file ahead of him to the one behind); in the inner lane, as before."""
    base = dict(law="improved", lane_gain=12.0, lane_half_m=0.32, lane_out_m=1.0, lane_level_lead=0.5)
    outer = SurroundConfig(**base, lane_outer_level_lead=0.0)  # type: ignore[arg-type]
    same = SurroundConfig(**base, lane_outer_level_lead=1.0)  # type: ignore[arg-type]
    walking = (1.0, 0.0)

    def aim(config: SurroundConfig, he: tuple[float, float]) -> Sequence[float] | None:
        law = ImprovedSurroundController(config)
        for _ in range(40):  # the lane ramped in
            law.step_plain([], [], he, walking, DT, human_velocity=walking)
        return law._aim(he, walking)

    # 0.9 m to his side, level with him: half the lead (0.4 m ahead of him) without it, none with it
    assert aim(same, (0.0, 0.9)) == pytest.approx((0.4, 0.9))
    assert aim(outer, (0.0, 0.9)) == pytest.approx((0.0, 0.9))
    # in the inner lane, or not level with him: unchanged
    assert aim(outer, (0.0, 0.3)) == aim(same, (0.0, 0.3))
    assert aim(outer, (-1.0, 0.9)) == aim(same, (-1.0, 0.9))


def test_the_humans_track_lag_counts_along_his_walk_only() -> None:
    """His braking since his track last saw him (``track_lag_s``) changes his speed along his walk: a robot level
    with him (his walk across the line to it) is not made to back off, where a neighbour pushed about may have
    slowed any way; ahead of him or behind him the allowance is the neighbours' (docs/SURROUND.md, item 14)."""
    law = ImprovedSurroundController(IMPROVED)
    c = IMPROVED
    touching = c.human_clearance_m + c.robot_radius_m
    lost = c.brake_mps2 * c.track_lag_s
    # beside him, 0.45 m off (inside his margin): he walks past, the robot need not move away
    beside = law._stop_rule(0.0, 0.45, 1.0, 0.0, touching, c.human_margin_m, walker=True)
    assert beside is not None and beside[2] == pytest.approx(0.0)
    pushed = law._stop_rule(0.0, 0.45, 1.0, 0.0, touching, c.human_margin_m)
    assert pushed is not None and pushed[2] == pytest.approx(-lost)
    # he comes at it from behind, or walks on ahead of it: as for any body
    for x, y in ((-0.45, 0.0), (0.6, 0.0)):
        his = law._stop_rule(x, y, 1.0, 0.0, touching, c.human_margin_m, walker=True)
        body = law._stop_rule(x, y, 1.0, 0.0, touching, c.human_margin_m)
        assert his == pytest.approx(body)
    # coming at it diagonally: the share of his braking along the line to it, between the two
    his = law._stop_rule(-0.35, 0.3, 1.0, 0.0, touching, c.human_margin_m, walker=True)
    body = law._stop_rule(-0.35, 0.3, 1.0, 0.0, touching, c.human_margin_m)
    assert his is not None and body is not None
    cosine = 0.35 / math.hypot(0.35, 0.3)
    assert his[2] - body[2] == pytest.approx(lost * (1 - cosine))
    # a human standing still has nothing to lose
    still = law._stop_rule(0.45, 0.0, 0.0, 0.0, touching, c.human_margin_m, walker=True)
    assert still is not None and still[2] == pytest.approx(0.0)


def test_the_wake_rule_takes_a_robot_outside_the_lane_into_the_path_of_the_neighbour_ahead() -> None:
    """The wake rule (docs/SURROUND.md, item 14): 0.5 m to the right of the walking human's line and 1 m behind
    him, with a neighbour 0.5 m ahead of it 0.1 m nearer his line, a robot moves toward the neighbour's offset at
    ``wake_rate`` times the difference; not level with him, not with a neighbour further out or off its path."""
    off = SurroundConfig(law="improved", wake_rate=0.0)
    walking = (1.0, 0.0)

    def command(config: SurroundConfig, he: tuple[float, float], neighbour: tuple[float, float]) -> tuple[float, float]:
        law = ImprovedSurroundController(config)
        v = (0.0, 0.0)
        for _ in range(30):  # the lane's ramp in
            v = law.step_plain(
                [neighbour], [], he, (1.0, 0.0), DT, human_velocity=walking, neighbour_velocities=[walking]
            )
        return v

    behind = (-1.0, 0.5)  # he is 1 m behind the robot, his line 0.5 m to its left
    woken = command(IMPROVED, behind, (0.5, 0.1))
    assert woken[1] >= IMPROVED.wake_rate * 0.1 - 1e-9
    assert command(off, behind, (0.5, 0.1))[1] < woken[1] - 0.05
    level = (-0.3, 0.5)  # beside him: the rule leaves it to link those ahead of him to those behind
    assert command(IMPROVED, level, (0.5, 0.1)) == command(off, level, (0.5, 0.1))
    for neighbour in ((0.5, -0.1), (0.5, 0.3), (0.9, 0.1)):  # further out; off its path; beyond reach
        assert command(IMPROVED, behind, neighbour) == command(off, behind, neighbour)


def test_the_wall_rule_turns_a_command_aimed_just_inside_a_point_to_pass_it() -> None:
    """A robot sliding along a wall whose command is a few degrees into the disc round an end point passes it (the
    tangent changes the command less than the stop would) rather than braking to a stop there."""
    point = [(0.3, -0.13)]  # 23 degrees to its right; the disc (its radius and the margin) spans 25 degrees
    v = ImprovedSurroundController(IMPROVED).step_plain([], [], None, (1.0, 0.0), DT, walls=point)
    assert math.hypot(*v) > 0.95 and v[1] > 0.0  # on at speed, turned off the point's side
    from petswarm.controllers.surround_improved import WALL_MARGIN_M

    x, y = point[0]
    d = math.hypot(x, y)
    clear = IMPROVED.robot_radius_m + WALL_MARGIN_M
    assert (v[0] * x + v[1] * y) / (d * math.hypot(*v)) <= math.sqrt(1 - (clear / d) ** 2) + 1e-9  # on the tangent
