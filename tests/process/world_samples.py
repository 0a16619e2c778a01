"""World frames in the hub's format (petswarm/lab/watch_frames.py) for tests of ``petswarm watch``: a user walking
east with a swarm around it, one robot shining IR at a time, obstacles, and radio events now and then."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

OBSTACLES = [
    {"kind": "circle", "x": 3.0, "y": 2.2, "r": 0.5},
    {"kind": "wall", "x0": -1.0, "y0": -2.5, "x1": 7.0, "y1": -2.5},
    {"kind": "rect", "x0": 5.5, "y0": 1.0, "x1": 6.5, "y1": 1.6},
]


def frame(k: int, robots: int, dt_us: int = 100_000, pan: int = 0x2A41) -> dict[str, Any]:
    """Frame ``k``: the user at x = 0.05 k m, robots on a circle of 1 m around it, turning slowly."""
    t_us = k * dt_us
    ux = 0.05 * k
    user = {"id": "1", "kind": "user", "x": ux, "y": 0.0, "yaw": 0.0, "vx": 0.5, "vy": 0.0, "radius": 0.25}
    bodies = [user]
    for i in range(robots):
        angle = 2 * math.pi * i / robots + 0.02 * k
        ref = [ux + math.cos(angle), math.sin(angle)]
        # each robot lags its reference a little, so reference and body are both visible
        x, y = ux + 0.9 * math.cos(angle - 0.1), 0.9 * math.sin(angle - 0.1)
        bodies.append(
            {
                "id": str(i + 1),
                "kind": "robot",
                "x": x,
                "y": y,
                "yaw": angle + math.pi / 2,
                "vx": 0.5,
                "vy": 0.0,
                "radius": 0.15,
                "pan_id": pan if i < robots - 1 else 0x1000,  # the last one is still waiting on its own PAN
                "ir": "transmit" if i == (k // 5) % robots else "receive",
                "state": "master-driving" if i == 0 else "slave-driving",
                "role": "master" if i == 0 else "slave",
                "reference": ref if i else None,
            }
        )
    events = [{"kind": "collision" if k % 20 == 0 else "loss", "node": "2", "t_us": t_us}] if k % 10 == 0 else []
    return {
        "v": 1,
        "t_us": t_us,
        "wall": 1_700_000_000.0 + t_us / 1e6,
        "bodies": bodies,
        "obstacles": OBSTACLES,
        "collisions": k // 30,
        "radio": {"delivered": 12 * k, "collided": k // 4, "lost": k // 10},
        "events": events,
    }


def write_record(run_dir: Path, frames: int, robots: int) -> Path:
    """A run record directory holding ``world.jsonl`` with ``frames`` frames."""
    run_dir.mkdir(parents=True, exist_ok=True)
    lines = [json.dumps(frame(k, robots)) for k in range(frames)]
    (run_dir / "world.jsonl").write_text("\n".join(lines) + "\n")
    return run_dir
