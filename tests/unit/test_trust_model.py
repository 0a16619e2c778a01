"""The trust model's pure parts: the hub's access control, TLS settings and what counts as our robot."""

from __future__ import annotations

from petswarm.lab.runtime import is_robot_command
from radio_hub.link.trust import OPERATOR, TransportSecurity, access_control, tls_settings


def _allowed(acl: dict, subject: str, flow: str, message: str) -> set[str]:
    """The key expressions ``subject`` is allowed for ``message`` in ``flow``."""
    policies = [p for p in acl["policies"] if subject in p["subjects"]]
    rules = {r["id"]: r for r in acl["rules"]}
    keys: set[str] = set()
    for policy in policies:
        for rule in (rules[r] for r in policy["rules"]):
            if flow in rule["flows"] and message in rule["messages"]:
                keys.update(rule["key_exprs"])
    return keys


def test_a_robot_publishes_only_on_its_own_up_key_and_nobody_on_a_downlink() -> None:
    acl = access_control(3)
    assert acl["default_permission"] == "deny"
    assert _allowed(acl, "robot-2", "ingress", "put") == {"petswarm/*/up/robot-2"}
    assert _allowed(acl, "user-1", "ingress", "put") == {"petswarm/*/up/user-1"}
    assert _allowed(acl, OPERATOR, "ingress", "put") == {"petswarm/*/robots/ctl"}
    everyone = [s["id"] for s in acl["subjects"]]
    assert len(everyone) == 1 + 2 * 3
    for subject in everyone:
        published = _allowed(acl, subject, "ingress", "put")
        assert not any("/down/" in key or key.endswith("**") for key in published), (subject, published)
        assert not _allowed(acl, subject, "ingress", "declare_queryable") - {f"petswarm/*/robot/{subject[6:]}/ctl"}
    assert _allowed(acl, "robot-2", "egress", "put") >= {"petswarm/*/down/robot-2"}
    assert "petswarm/*/down/robot-1" not in _allowed(acl, "robot-2", "egress", "put")


def test_tls_settings_of_each_side() -> None:
    mutual = TransportSecurity("ca.pem", "me.pem", "me.key")
    assert tls_settings(mutual, "router") == {
        "root_ca_certificate": "ca.pem",
        "listen_certificate": "me.pem",
        "listen_private_key": "me.key",
        "enable_mtls": True,
    }
    assert tls_settings(mutual, "client")["connect_certificate"] == "me.pem"
    assert tls_settings(TransportSecurity(ca="ca.pem"), "client") == {"root_ca_certificate": "ca.pem"}
    assert tls_settings(TransportSecurity(), "router") == {}


def test_only_a_petswarm_robot_command_of_that_id_and_world_is_our_robot() -> None:
    run_child = ["/usr/bin/python3", "-m", "cli", "robot", "--id", "5", "--hub", "tcp/x:1", "--world", "w"]
    assert is_robot_command(run_child, "w", 5)
    assert not is_robot_command(run_child, "other", 5)
    assert not is_robot_command(run_child, "w", 4)
    assert is_robot_command(["/venv/bin/python", "/venv/bin/petswarm", "robot", "--id=3"], "default", 3)
    assert not is_robot_command(["/bin/sleep", "robot", "--id", "3"], "default", 3)
    assert not is_robot_command(["/venv/bin/petswarm", "hub", "--world", "w"], "w", 1)
