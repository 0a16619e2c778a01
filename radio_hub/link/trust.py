"""Who may talk to a hub, and about what: TLS settings and the hub's zenoh access control.

The trust model (README "Trust model"): on loopback every process is the operator's own and nothing is
checked. Across hosts the hub listens on TLS with client certificates (mutual TLS): a process without a
certificate signed by the run's CA cannot open a session at all, and a certificate's common name is its
role. The hub is the zenoh router, so zenoh's own access control on it decides, per common name, which
messages may come in and go out on which keys (rules keyed on ``petswarm/*/...`` hold for every world):

- ``robot-<n>`` publishes only on its own ``up`` key, holds only its own liveliness token, subscribes only
  to its own ``down`` key and the all-robots control topic, and serves only its own control queryable;
- ``user-<n>`` the same without a control queryable;
- ``operator`` (``petswarm run/stats/chaos/swarm/watch`` run by a person) asks queries anywhere in
  ``petswarm/**``, commands every robot on ``robots/ctl`` and watches the world, but publishes no frames
  and serves no queryable;
- anyone else, and every publication on ``down/**`` from outside, is refused: only the hub (the router's
  own session, which no rule constrains) speaks on the nodes' downlinks.

This module imports no zenoh: it builds the JSON the zenoh config takes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

OPERATOR = "operator"
"""The common name of an operator's certificate."""
DEFAULT_ACL_IDS = 64
"""Robots robot-1..robot-64 and users user-1..user-64 get node rights unless the hub is told otherwise."""

_W = "petswarm/*"
_NODE_IN = ("declare_subscriber", "declare_liveliness_subscriber", "liveliness_query")
"""What every node asks of the router about keys that are not its own (robots/ctl, the hub's token)."""


@dataclass(frozen=True)
class TransportSecurity:
    """A process's TLS files (PEM paths) and an optional zenoh config file everything else starts from.

    A hub with ``cert`` and ``key`` listens on TLS; with ``ca`` as well it asks every client for a
    certificate signed by that CA (mutual TLS) and enforces the access control. A client with ``ca``
    checks the hub's certificate; with ``cert`` and ``key`` it shows its own."""

    ca: str | None = None
    cert: str | None = None
    key: str | None = None
    zenoh_config: str | None = None
    acl_ids: int = DEFAULT_ACL_IDS

    @property
    def mutual(self) -> bool:
        """Whether this side asks for (hub) or shows (client) a certificate."""
        return bool(self.ca and self.cert and self.key)


def tls_settings(security: TransportSecurity, mode: str) -> dict[str, Any]:
    """The ``transport/link/tls`` settings of a router (``mode`` "router") or client; empty without TLS files."""
    tls: dict[str, Any] = {}
    if security.ca:
        tls["root_ca_certificate"] = security.ca
    if security.cert and security.key:
        side = "listen" if mode == "router" else "connect"
        tls[f"{side}_certificate"] = security.cert
        tls[f"{side}_private_key"] = security.key
    if security.mutual:
        tls["enable_mtls"] = True  # the hub asks for a client certificate; a client shows its own
    return tls


def _rule(rule_id: str, flow: str, messages: list[str], keys: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": keys}


def _node_rules(node: str, control: str | None) -> list[dict[str, Any]]:
    """What node ``node`` may send and receive; ``control`` is its control queryable's key (robots)."""
    own_in = [
        _rule(f"{node}-up", "ingress", ["put"], [f"{_W}/up/{node}"]),
        _rule(f"{node}-sub", "ingress", ["declare_subscriber"], [f"{_W}/down/{node}"]),
        _rule(f"{node}-alive", "ingress", ["liveliness_token"], [f"{_W}/alive/{node}/*"]),
    ]
    down = [f"{_W}/down/{node}"]
    if control is not None:
        own_in.append(_rule(f"{node}-ctl", "ingress", ["declare_queryable", "reply"], [control]))
        down.append(control)
    return [*own_in, _rule(f"{node}-out", "egress", ["put", "query"], down)]


def _common_rules() -> list[dict[str, Any]]:
    """What every node shares: the all-robots control topic and the hub's liveliness token."""
    shared = [f"{_W}/robots/ctl", f"{_W}/hub/alive"]
    return [
        _rule("node-in", "ingress", list(_NODE_IN), shared),
        _rule("node-out", "egress", ["put", "liveliness_token"], shared),
        # a client's publisher sends only while it knows of a matching subscriber: the hub's on each node's
        # up key (radio_hub.link.up_keys) must be declared to it (a node learns who listens, never what is said)
        _rule("node-matching", "egress", ["declare_subscriber"], [f"{_W}/up/*"]),
    ]


def _operator_rules() -> list[dict[str, Any]]:
    """An operator asks and watches; it publishes only whole-swarm commands and serves nothing."""
    everything = ["petswarm/**"]
    asks = ["query", "declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"]
    return [
        _rule("operator-in", "ingress", asks, everything),
        _rule("operator-command", "ingress", ["put"], [f"{_W}/robots/ctl"]),
        _rule("operator-out", "egress", ["put", "reply", "liveliness_token"], everything),
    ]


def access_control(acl_ids: int = DEFAULT_ACL_IDS) -> dict[str, Any]:
    """The hub's ``access_control`` config: deny by default, each role's rules for its certificate's name."""
    rules = _common_rules() + _operator_rules()
    subjects = [{"id": OPERATOR, "cert_common_names": [OPERATOR]}]
    policies = [{"id": OPERATOR, "rules": [r["id"] for r in _operator_rules()], "subjects": [OPERATOR]}]
    common = [r["id"] for r in _common_rules()]
    for n in range(1, acl_ids + 1):
        for node, control in ((f"robot-{n}", f"{_W}/robot/{n}/ctl"), (f"user-{n}", None)):
            own = _node_rules(node, control)
            rules += own
            subjects.append({"id": node, "cert_common_names": [node]})
            policies.append({"id": node, "rules": common + [r["id"] for r in own], "subjects": [node]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }
