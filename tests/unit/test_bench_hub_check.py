"""``petswarm bench hub --check``: the exit status names every missed target, with the load it was measured at."""

from petswarm.bench.hub import FPS_TARGET, check_targets, load_summary, targets


def _results(ratio: float, fps: float, lag_us: float, capacity: float = 11161.0) -> dict:
    load = {"start": 0.9, "end": 1.1}
    return {
        "rtt": {"ratio_p50": ratio, "pass": ratio <= 1.5, "load_average": load},
        "load": [
            {
                "label": "defaults",
                "nodes": 50,
                "frames_per_s": fps,
                "target_fps": min(FPS_TARGET, capacity),
                "pass": fps >= min(FPS_TARGET, capacity),
                "hub": {"lag_p99_us": lag_us},
                "load_average": load,
            }
        ],
    }


def _checked(results: dict, capsys) -> tuple[int, str]:
    results["targets"] = targets(results)
    return check_targets(results), capsys.readouterr().err


def test_every_target_met_exits_0(capsys):
    code, err = _checked(_results(1.4, 10500.0, 1500.0), capsys)
    assert code == 0
    assert "every target met" in err


def test_each_missed_target_is_named_with_its_load(capsys):
    code, err = _checked(_results(2.7, 2516.0, 9161.0), capsys)
    assert code == 1
    assert "MISS rtt.ratio_p50 = 2.70" in err
    assert "frames/s at 50 nodes = 2516.00" in err
    assert "lag p99 us = 9161.00" in err
    assert err.count("load average 0.90 -> 1.10") == 3


def test_a_lag_alone_fails_the_check(capsys):
    code, err = _checked(_results(1.2, 10100.0, 2500.0), capsys)
    assert code == 1
    assert err.count("MISS") == 1 and "lag p99" in err


def test_an_air_below_the_target_sets_the_throughput_target():
    class Snap:
        def __init__(self, delivered: int, t_s: float) -> None:
            per_node = {"delivered": delivered, "sent": delivered}
            config = {"mac": {"min_be": 3, "max_be": 5, "csma_enabled": True, "unit_backoff_us": 320}}
            config["mac"].update(cca_us=128, turnaround_us=192)
            self.stats = {"nodes": {"a": per_node}, "config": config, "channels": {}, "hub": {}}
            self.delivered, self.sent, self.t_s = delivered, delivered, t_s
            self.hub_cpu_s = self.hub_job_cpu_s = self.hub_world_cpu_s = self.gens_cpu_s = 0.0
            self.machine = (0.0, 1.0)

    lag = {k: 0 for k in ("lag_p50_us", "lag_p99_us", "lag_samples", "transport_gaps", "malformed")}
    results = []
    for delivered in (2000, 2300):  # 5 pairs: about 2,230 frames/s of air with the default MAC
        before, after = Snap(0, 0.0), Snap(delivered, 1.0)
        after.machine = (1.0, 2.0)
        after.stats["hub"] = lag
        results.append(load_summary("defaults", None, 10, 1, before, after, []))
    for summary in results:
        assert summary["target_fps"] == summary["model_capacity_fps"] < FPS_TARGET
    assert [summary["pass"] for summary in results] == [False, True]
