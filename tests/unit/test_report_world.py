"""``petswarm report`` on a scenario run: driving figures in text, trajectory and formation-error plots."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from petswarm.lab.report import report_command

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
SLAVE_OFFSET_M = 0.2  # robot 2 trails its reference by exactly this much, so its formation error is known


def _tick(k: int) -> dict[str, Any]:
    t = k * 0.02
    turning = t >= 3.0
    user_yaw = 0.6 * (t - 3.0) if turning else 0.0
    ux, uy = 0.5 * t, 0.3 * max(t - 3.0, 0.0) ** 2
    user = {"id": "1", "kind": "user", "x": ux, "y": uy, "yaw": user_yaw, "vx": 0.5, "vy": 0.0}
    user |= {"omega": 0.6 if turning else 0.0, "radius": 0.25}
    bodies = [user]
    for rid, (dx, dy, role) in enumerate([(1.0, 0.0, "master"), (0.0, 1.0, "slave"), (0.0, -1.0, "slave")], start=1):
        x, y = ux + dx, uy + dy
        reference = [x + SLAVE_OFFSET_M, y] if rid == 2 else None
        robot = {"id": str(rid), "kind": "robot", "x": x, "y": y, "yaw": user_yaw, "vx": 0.5, "vy": 0.0}
        robot |= {"omega": 0.6 if t >= 3.5 else 0.0, "radius": 0.15, "pan_id": 7, "ir": "receive"}
        robot |= {"state": f"{role}-driving", "role": role, "reference": reference}
        bodies.append(robot)
    obstacles = [
        {"kind": "circle", "x": 2.0, "y": 2.0, "r": 0.3},
        {"kind": "wall", "x0": -1, "y0": -2, "x1": 4, "y1": -2},
    ]
    radio = {"delivered": k, "collided": 0, "lost": 0}
    return {"v": 1, "t_us": int(t * 1e6), "bodies": bodies, "obstacles": obstacles, "collisions": 0, "radio": radio}


def _run_record(run: Path, *, with_world: bool) -> None:
    run.mkdir()
    (run / "events").mkdir()
    manifest = {
        "started": "20261122T000000Z",
        "seed": 5,
        "world": "test",
        "versions": {"petswarm": "0"},
        "options": {"robots": 3},
    }
    (run / "manifest.json").write_text(json.dumps(manifest))
    summary = {"ok": True, "nodes": {}, "faults": [{"at": 2.0, "op": "add", "fault": {"kind": "loss"}}]}
    (run / "summary.json").write_text(json.dumps(summary))
    if with_world:
        lines = [json.dumps(_tick(k)) for k in range(300)]
        # a killed hub leaves half a line behind
        (run / "world.jsonl").write_text("\n".join(lines) + '\n{"v": 1, "t_us": 6000000, "bod')


def test_report_renders_world_plots_and_prints_the_formation_error(tmp_path: Path, capsys: Any) -> None:
    run = tmp_path / "run"
    _run_record(run, with_world=True)

    assert report_command(argparse.Namespace(run=str(run), out=None)) == 0

    for name in ("trajectories.png", "formation_error.png"):
        data = (run / name).read_bytes()
        assert data.startswith(PNG_MAGIC), name
        assert len(data) > 5000, name
    out = capsys.readouterr().out
    assert f"formation error (all slaves): median {SLAVE_OFFSET_M:.3f} m" in out
    assert "user-master distance: median 1.00 m" in out
    assert "reaction to the user's turns" in out and "     3.0  " in out


def test_report_without_world_log_draws_no_driving_plots(tmp_path: Path, capsys: Any) -> None:
    run = tmp_path / "run"
    _run_record(run, with_world=False)

    assert report_command(argparse.Namespace(run=str(run), out=None)) == 0

    assert (run / "report.png").exists()
    assert not (run / "trajectories.png").exists()
    assert "formation error" not in capsys.readouterr().out


def test_report_lists_robots_in_number_order(tmp_path: Path, capsys: Any) -> None:
    run = tmp_path / "run"
    _run_record(run, with_world=False)
    for rid in (1, 2, 10, 11, 3):
        event = {"t": 1.0, "mono": 0.0, "kind": "start", "robot_id": rid, "state": "waiting"}
        (run / "events" / f"robot-{rid}.jsonl").write_text(json.dumps(event) + "\n")
    assert report_command(argparse.Namespace(run=str(run), out=None, json=False)) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines() if " events; " in line]
    assert listed == ["robot-1", "robot-2", "robot-3", "robot-10", "robot-11"], listed
