"""``petswarm experiment``: what makes a run pass, and the figures it aggregates (no processes here)."""

from __future__ import annotations

from pathlib import Path

import pytest

from petswarm.lab.experiment import WAIVABLE, judge, load

ROOT = Path(__file__).resolve().parents[2]
FEWER = "only 1 of the 3 robots it could take joined the swarm (the master found 1 available)"
PAIRS = "not every robot heard every other robot"


def test_a_run_passes_on_what_its_experiment_requires() -> None:
    everything = ["all_pairs_heard", "full_swarm"]
    assert judge(0, [], everything) == (True, [], [])
    # by default an experiment asks what `petswarm run` asks
    assert judge(1, [FEWER, PAIRS], everything) == (False, [FEWER, PAIRS], [])
    # an experiment that measures the swarm under loss reports its size and the ping phase, not requires them
    assert judge(1, [FEWER, PAIRS], []) == (True, [], [FEWER, PAIRS])
    assert judge(1, [FEWER, PAIRS], ["full_swarm"]) == (False, [FEWER], [PAIRS])
    # states that disagree with the master's, a broken invariant or a failed process always fail a run
    disagree = "robot 3 is waiting on PAN 0x1000 after organizing; the master says slave-driving on 0x2a41"
    assert judge(1, [FEWER, disagree], []) == (False, [disagree], [FEWER])
    assert judge(1, ["failed: hub exited with code 2"], []) == (False, ["failed: hub exited with code 2"], [])
    assert judge(130, ["interrupted"], [])[0] is False


def test_the_waivable_problems_are_worded_as_the_run_words_them() -> None:
    # the experiment knows them by their wording: if petswarm/lab/run.py rewords one, this says so
    source = (ROOT / "petswarm" / "lab" / "run.py").read_text()
    assert all(wording in source for wording in WAIVABLE.values()), WAIVABLE


def test_the_example_experiment_requires_what_it_is_about() -> None:
    spec = load(ROOT / "examples" / "experiment-loss.toml")
    assert spec["require"] == []  # the swarm's size and the ping phase under loss are measured, not required
    assert spec["run"]["organize"] == 3 and spec["faults"][0]["p"] == 0.3
    assert spec["faults"][0]["at"] == 0  # the whole run under the fault, so the measured loss is the fault's
    assert spec["run"]["clock"] == "model"  # each seed's run repeats exactly, whatever the machine's load


@pytest.mark.parametrize(
    ("run_table", "error"),
    [
        ('clock = "sundial"', "[run] clock is one of wall, model, lockstep, not 'sundial'"),
        ('profile = "mars"', "unknown profile 'mars'"),
    ],
)
def test_an_experiment_with_an_unknown_clock_or_profile_is_refused_naming_it(
    tmp_path: Path, run_table: str, error: str
) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(f"repetitions = 1\n[run]\nrobots = 2\n{run_table}\n")
    with pytest.raises(ValueError, match=r"bad\.toml") as refused:
        load(path)
    assert error in str(refused.value)


def test_the_lost_fraction_of_a_30_percent_loss_fault_reads_about_0_3() -> None:
    """Five robots in the emulated air under a 30 % loss fault, each broadcasting a ping and answering every
    ping with an acknowledged unicast pong (the robots' traffic): receptions are counted at every receiver in
    range, and most of them are filtered (a pong is for one robot), which the fraction must count too."""
    from petswarm.lab.experiment import _aggregate
    from tests.unit.helpers import data, medium, place, run_to_idle

    m = medium(seed=3)
    nodes = [place(m, short, 0.5 * short) for short in range(1, 6)]
    m.chaos.add({"kind": "loss", "p": 0.3}, 0, 0.0)
    now, token = 0, 0
    for seq in range(60):
        for src in range(1, 6):
            for dst in [0xFFFF, *(d for d in range(1, 6) if d != src)]:
                now, token = now + 20_000, token + 1  # 20 ms apart: nothing collides, only the fault loses frames
                run_to_idle(m, m.submit(nodes[src - 1], data(src, dst=dst, seq=seq % 256), token, now))
    counters = [m.node_counters[n].to_dict() for n in nodes]
    assert sum(c["collided"] for c in counters) == 0 and sum(c["filtered"] for c in counters) > 0
    radio = ("sent", "delivered", "collided", "lost", "filtered", "mac_retries")  # the counters a row sums
    row = {"ok": True, "organize_ms": None, "retries": None, **{k: sum(c[k] for c in counters) for k in radio}}
    assert 0.27 <= _aggregate([row])["lost_fraction"] <= 0.33


def test_a_bad_experiment_file_is_refused_with_exit_2_naming_it_once(tmp_path: Path, capsys) -> None:
    from cli.main import main

    path = tmp_path / "bad.toml"
    path.write_text('repetitions = 1\n[run]\nclock = "sundial"\n')
    assert main(["experiment", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count(str(path)) == 1 and "clock is one of wall, model, lockstep" in err, err
