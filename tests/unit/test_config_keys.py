"""Every file petswarm reads refuses a key it does not know, naming the file, the table, the key and the
nearest valid name: a misspelt key must never fall back silently to a default."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from petswarm.lab.experiment import load as load_experiment
from petswarm.scenario import ScenarioError
from petswarm.scenario import load as load_scenario
from radio_hub.shell.hub import load_config

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = """
name = "typo"
duration_s = 10
[user]
owner = 1
path = [ {walk = 4, speed = 1}, {turn = 90, rate = 45}, {stop = 2} ]
watch = [ {at = 1, request = "follow"}, {at = 2, request = "organize", robots = 1, shape = "column"} ]
[robots]
count = 2
"""


def _refused(error: Exception, file: Path, table: str, key: str, nearest: str | None) -> None:
    text = str(error)
    assert str(file) in text, text
    assert table in text, text
    assert repr(key) in text, text
    assert (f"did you mean {nearest!r}" in text) if nearest else ("did you mean" not in text), text


def _scenario(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scenario.toml"
    path.write_text(text)
    return path


def test_the_base_scenario_of_these_tests_loads(tmp_path: Path) -> None:
    scenario = load_scenario(_scenario(tmp_path, SCENARIO))
    assert scenario.robot_count == 2 and scenario.user is not None and len(scenario.user.legs) == 3


@pytest.mark.parametrize(
    "old, new, table, key, nearest",
    [
        ("count = 2", "cuont = 3", "[robots]", "cuont", "count"),
        ("{walk = 4, speed = 1}", "{walk = 4, sped = 1}", "[user] path[0]", "sped", "speed"),
        ("{turn = 90, rate = 45}", "{turn = 90, rat = 45}", "[user] path[1]", "rat", "rate"),
        ("{walk = 4, speed = 1}", "{walk = 4, turn = 1}", "[user] path[0]", "turn", None),
        ("owner = 1", "ownr = 1", "[user]", "ownr", "owner"),
        ("robots = 1, shape", "robot = 1, shape", "[user] watch[1]", "robot", "robots"),
        ('request = "follow"', 'request = "follow", robots = 2', "[user] watch[0]", "robots", None),
        ("duration_s = 10", "duraton_s = 10", "the top level", "duraton_s", "duration_s"),
        ("[robots]", "[hub.world]\nrobot_radius = 0.1\n[robots]", "[world]", "robot_radius", "robot_radius_m"),
        ("[robots]", "[hub.wrold]\ntick_s = 0.02\n[robots]", "[hub]", "wrold", "world"),
        ("[robots]", "[hub.mac]\nmin_bee = 3\n[robots]", "[mac]", "min_bee", "min_be"),
        ("[robots]", "[surround]\nenabled = true\nstifness = 8\n[robots]", "[surround]", "stifness", "stiffness"),
        (
            "[robots]",
            '[[obstacles]]\nkind = "rect"\nx0 = 0\ny0 = 0\nx_1 = 1\ny1 = 1\n[robots]',
            "[[obstacles]][0]",
            "x_1",
            "x1",
        ),
        ("[robots]", '[[faults]]\nat = 1\nkind = "loss"\npp = 0.3\n[robots]', "[[faults]][0]", "pp", "p"),
        ("[robots]", "[[faults]]\nat = 1\nclear = true\nid = 2\nnode = 3\n[robots]", "[[faults]][0]", "node", None),
    ],
)
def test_a_misspelt_scenario_key_is_refused(
    tmp_path: Path, old: str, new: str, table: str, key: str, nearest: str | None
) -> None:
    assert old in SCENARIO
    path = _scenario(tmp_path, SCENARIO.replace(old, new, 1))
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    _refused(err.value, path, table, key, nearest)


def test_a_misspelt_hub_config_key_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "medium.toml"
    for text, table, key, nearest in (
        ("[mac]\nmin_bee = 3\n", "[mac]", "min_bee", "min_be"),
        ("[loss.gilbert_elliot]\np_good_to_bad = 0.1\n", "[loss]", "gilbert_elliot", "gilbert_elliott"),
        ("[wrold]\ntick_s = 0.02\n", "the top level", "wrold", "world"),
        ("[ir]\nrelative_nois = 0\n", "[ir]", "relative_nois", "relative_noise"),
        ('[[obstacles]]\nkind = "wall"\nx0 = 0\ny0 = 0\nx1 = 1\ny_1 = 1\n', "[[obstacles]][0]", "y_1", "y1"),
    ):
        path.write_text(text)
        with pytest.raises(ValueError) as err:
            load_config(path)
        _refused(err.value, path, table, key, nearest)


def test_a_misspelt_experiment_key_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "experiment.toml"
    base = 'name = "e"\nrepetitions = 2\n[run]\nrobots = 3\n[[faults]]\nat = 0.5\nkind = "loss"\np = 0.3\n'
    assert load_experiment(_write(path, base))["seeds"] == [1, 2]
    for old, new, table, key, nearest in (
        ("repetitions", "repetitons", "the top level", "repetitons", "repetitions"),
        ("robots = 3", "robtos = 3", "[run]", "robtos", "robots"),
        ("p = 0.3", "pp = 0.3", "[[faults]][0]", "pp", "p"),
    ):
        with pytest.raises(ValueError) as err:
            load_experiment(_write(path, base.replace(old, new)))
        _refused(err.value, path, table, key, nearest)


def test_an_experiment_names_a_misspelt_key_of_its_hub_config(tmp_path: Path) -> None:
    config = _write(tmp_path / "air.toml", "[range]\ntx_rnge_m = 10\n")
    path = _write(tmp_path / "experiment.toml", f'[run]\nrobots = 3\nconfig = "{config}"\n')
    with pytest.raises(ValueError) as err:
        load_experiment(path)
    _refused(err.value, config, "[range]", "tx_rnge_m", "tx_range_m")


def test_the_surround_config_option_names_the_nearest_key() -> None:
    import argparse

    from petswarm.lab.arguments import surround_config

    with pytest.raises(argparse.ArgumentTypeError, match=re.escape("'stifness' (did you mean 'stiffness'?)")):
        surround_config('{"stifness": 8}')


def test_every_shipped_scenario_config_and_experiment_loads() -> None:
    scenarios = [*sorted((ROOT / "scenarios").glob("*.toml")), ROOT / "examples" / "scenario-compose.toml"]
    assert len(scenarios) >= 8
    for path in scenarios:
        load_scenario(path)
    for path in (ROOT / "examples").glob("medium-*.toml"):
        load_config(path)
    for path in (ROOT / "examples").glob("experiment-*.toml"):
        load_experiment(path)


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path
