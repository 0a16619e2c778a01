"""World and node names become zenoh key chunks: only plain ones pass ``check_name``."""

from __future__ import annotations

import pytest

from radio_hub.link.keys import Keys, check_name


@pytest.mark.parametrize("name", ["robot-1", "user_1", "a.b", "x" * 64, "7"])
def test_plain_names_pass(name: str) -> None:
    assert check_name("node", name) == name


@pytest.mark.parametrize("name", ["", "x" * 65, "a/b", "a*", "$*", "a b", "robot-1\n", "\nrobot-1", "wörld"])
def test_names_that_would_change_a_key_expression_are_refused(name: str) -> None:
    with pytest.raises(ValueError, match="must be 1-64 letters"):
        check_name("node", name)


def test_a_world_name_is_checked_when_its_keys_are_made() -> None:
    assert Keys("w-1").up("robot-2") == "petswarm/w-1/up/robot-2"
    with pytest.raises(ValueError):
        Keys("w\n")
