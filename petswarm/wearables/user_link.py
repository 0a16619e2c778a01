"""What the user's wearables and their robot say over BLE, and what the LF bursts carry.

BLE messages are msgpack maps with a kind ``k``:

- belt -> robot ``owner`` (``d``: metres): the belt woke on this robot's pattern within wake range;
- belt -> robot ``lf`` (``seq``, ``dl``, ``dr``: metres from the left and right antenna);
- belt -> robot ``activity`` (``Activity.to_dict()`` plus ``t``: the belt's time of the sample);
- watch -> robot ``request`` (``request`` and its arguments, as in a scenario's watch list);
- robot -> belt ``alert`` (``reason``) and ``state`` (``state``: the robot's state after a request);
- robot -> belt ``pair`` (``robot``: a robot id): the master handed its role to that robot (Table 3,
  Change); the belt loads that robot's pattern into its wake-up register and takes it as its owner. The
  paper gives no re-pairing protocol: this message is the project's choice.

An LF burst's 4 data bytes: the robot's id (2 bytes, big endian), a sequence number, and the purpose
(0 = wake-up while waiting for a user, 1 = tracking its owner).
"""

from __future__ import annotations

from typing import Any

import msgpack

KINDS = ("owner", "lf", "activity", "request", "alert", "state", "pair")
LF_WAKE, LF_TRACK = 0, 1


def encode(kind: str, **fields: Any) -> bytes:
    """One BLE message."""
    if kind not in KINDS:
        raise ValueError(f"BLE message kind must be one of {KINDS}, not {kind!r}")
    return msgpack.packb({"k": kind, **fields}, use_bin_type=True)


def decode(payload: bytes) -> dict[str, Any]:
    """A BLE message as a map; ValueError on anything malformed."""
    try:
        body = msgpack.unpackb(payload, raw=False)
    except Exception as err:  # msgpack raises several unrelated types on garbage
        raise ValueError(f"not msgpack ({type(err).__name__})") from None
    if not isinstance(body, dict) or body.get("k") not in KINDS:
        raise ValueError("not a BLE message of this protocol")
    return body


def robot_node(robot_id: int) -> str:
    """A robot's node id on the hub (what BLE messages are addressed to)."""
    return f"robot-{robot_id}"


def lf_data(robot_id: int, seq: int, purpose: int) -> bytes:
    """The 4 data bytes of a burst."""
    return bytes([(robot_id >> 8) & 0xFF, robot_id & 0xFF, seq & 0xFF, purpose & 0xFF])


def parse_lf_data(data: bytes) -> tuple[int, int, int]:
    """(robot id, sequence, purpose) of a burst's data; ValueError if it is not 4 bytes."""
    if len(data) != 4:
        raise ValueError(f"LF data is 4 bytes, got {len(data)}")
    return (data[0] << 8) | data[1], data[2], data[3]
