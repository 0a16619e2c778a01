"""The world's contact settling: its per-pair shortcut settles every crowd as the full pair loop does, bit for bit."""

from __future__ import annotations

import numpy as np

from radio_hub.physics.world import Body, Obstacle, World, WorldConfig, _push_apart, _unit


def _settled_as_before(world: World) -> set[tuple[str, str]]:
    """``World._settled_contacts`` without the shortcut (every pair's norm taken), on ``world``'s bodies."""
    contacts: set[tuple[str, str]] = set()
    bodies = list(world.bodies.values())
    for i, a in enumerate(bodies):
        for b in bodies[i + 1 :]:
            gap = a.pose[:2] - b.pose[:2]
            dist = float(np.hypot(*gap))
            overlap = a.radius + b.radius - dist
            if overlap > 0:
                contacts.add((a.body_id, b.body_id) if a.body_id < b.body_id else (b.body_id, a.body_id))
                _push_apart(a, b, gap, dist, overlap)
        for k, push in _circle_pushes_as_before(world, a):
            contacts.add((a.body_id, f"obstacle-{k}"))
            if a.kind == "robot":
                a.pose[:2] += push
    return contacts


def _circle_pushes_as_before(world: World, body: Body) -> list[tuple[int, np.ndarray]]:
    """``World._obstacle_pushes`` for circles, every norm taken."""
    pushes = []
    p = body.pose[:2]
    for k, obstacle in enumerate(world.obstacles):
        gap = p - (obstacle.x, obstacle.y)
        dist = float(np.hypot(*gap))
        depth = body.radius + obstacle.r - dist
        if depth > 0:
            pushes.append((k, _unit(gap) * depth))
    return pushes


def _crowd(seed: int) -> World:
    rng = np.random.default_rng(seed)
    world = World(WorldConfig(robot_radius_m=0.1))
    world.set_obstacles([Obstacle("circle", x=0.6, y=0.3, r=0.4), Obstacle("circle", x=-0.5, y=-0.5, r=0.2)])
    for k in range(int(rng.integers(2, 24))):
        x, y = rng.uniform(-1.2, 1.2, 2).tolist()
        if k % 5 == 0 and k:  # some exactly at a leg's length from the last (the shortcut's edge)
            last = world.bodies[f"r{k - 1}"].pose
            x, y = float(last[0]) + 0.2, float(last[1])
        world.add(f"r{k}", "robot" if k else "user", x, y, 0.0)
    return world


def test_settling_with_the_per_pair_shortcut_moves_and_counts_as_every_norm_did() -> None:
    touched = 0
    for seed in range(150):
        mine, theirs = _crowd(seed), _crowd(seed)
        got, want = mine._settled_contacts(), _settled_as_before(theirs)
        assert got == want
        touched += bool(got)
        for name, body in mine.bodies.items():
            assert body.pose.tobytes() == theirs.bodies[name].pose.tobytes()
    assert touched > 100  # crowds in contact, so bodies were pushed and later pairs saw the moved poses


def test_hypot_is_never_below_its_larger_leg() -> None:
    # what the shortcut rests on, for the norms it skips
    rng = np.random.default_rng(4)
    legs = np.concatenate([rng.uniform(-1, 1, (200_000, 2)), rng.uniform(-1e-3, 1e-3, (50_000, 2))])
    legs[::7, 1] = 0.0
    norms = np.hypot(legs[:, 0], legs[:, 1])
    assert (norms >= np.maximum(np.abs(legs[:, 0]), np.abs(legs[:, 1]))).all()
