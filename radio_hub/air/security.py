"""IEEE 802.15.4-2011 clause 9 link-layer security for the emulated air: AES-CCM*, the auxiliary security header,
frame counters with replay protection, and keys by index. Off by default; pure code (no I/O, no clock).

A secured data frame (``Frame.secured``: the frame control's Security Enabled bit, frame version 1) carries in
its MAC payload field

    auxiliary security header | encrypted payload | MIC

- the auxiliary security header (9.4): security control (1 byte: security level in bits 0-2, key identifier
  mode in bits 3-4), frame counter (4 bytes, little-endian), key identifier (key identifier mode 1: one byte,
  the key index; the key source is implicit). 6 bytes.
- security level 5 (ENC-MIC-32) or 6 (ENC-MIC-64): the payload is encrypted and authenticated with a 4- or
  8-byte MIC. With a MIC length above zero, CCM* is CCM (Annex B), which ``cryptography``'s ``AESCCM`` computes;
  the authenticated data ``a`` is the MAC header with the auxiliary security header (9.3.4).
- the nonce (9.3.2.2): source address (8 bytes), frame counter (4 bytes, big-endian), security level (1 byte).
  The emulated robots address each other by short address only and keep no device table of extended addresses,
  so the nonce's source address is the sender's PAN ID and short address (big-endian), padded with 0xFF: unique
  per sender within the air, which is what the nonce needs (one frame counter per sender, shared by its keys).
- replay protection (9.2.5): a frame is accepted only if its frame counter is at least the next one expected
  from that sender under that key; then the next expected is the counter plus one. A counter of 0xFFFFFFFF is
  never sent (the sender's counter is exhausted) nor accepted.

Keys: index 1 is the network key, pre-shared (a file or a profile); index 2 is a swarm's key, which the master
hands to each member in the join handshake (inside the join notice, itself secured with the network key). ACK
frames are not secured (the standard does not secure them either).

What a receiver refuses is counted in ``LinkSecurity.counters``: ``unsecured`` (a frame without security where
security is required), ``mic_failed`` (the MIC does not verify: a wrong key, a forgery, a changed bit),
``replayed`` (a frame counter already seen), ``unknown_key`` (a key index this node does not hold),
``malformed`` (an auxiliary header that does not parse or an unsupported level).
"""

from __future__ import annotations

import hashlib
import struct
from collections import OrderedDict
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from radio_hub.air.mac import FCS_LEN, MAX_PSDU, Frame, FrameType

NETWORK_KEY = 1
"""The key index of the pre-shared network key."""
SWARM_KEY = 2
"""The key index of a swarm's key (handed over in the join handshake)."""
LEVELS = {4: 5, 8: 6}
"""Security level by MIC length: ENC-MIC-32 (5) and ENC-MIC-64 (6)."""
MIC_OF_LEVEL = {level: mic for mic, level in LEVELS.items()}
KEY_ID_MODE = 1
"""Key identifier mode 1: the key is named by a one-byte key index (the key source is implicit)."""
AUX_LEN = 6
"""Security control (1), frame counter (4), key index (1)."""
COUNTER_MAX = 0xFFFFFFFF
"""A frame counter of this value is never used (9.3.3: the counter is exhausted)."""
SENDERS_KEPT = 4096
"""Senders whose next expected frame counter a receiver remembers (least recently heard forgotten first)."""

_AUX = struct.Struct("<BIB")
_NONCE = struct.Struct(">HHIIB")


class SecurityError(ValueError):
    """A secured frame that cannot be accepted; ``reason`` is the counter it moves."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


def load_key(text: str) -> bytes:
    """A 128-bit key from 32 hex digits (whitespace ignored); ValueError otherwise."""
    digits = "".join(text.split())
    try:
        key = bytes.fromhex(digits)
    except ValueError:
        raise ValueError("a network key is 32 hex digits (128 bits)") from None
    if len(key) != 16:
        raise ValueError(f"a network key is 128 bits (32 hex digits), not {len(key) * 8}")
    return key


def read_key_file(path: str | Path) -> bytes:
    """A network key from a file of 32 hex digits; ValueError (or OSError) otherwise."""
    with Path(path).open("rb") as stream:
        data = stream.read(256)
    return load_key(data.decode("ascii", errors="replace"))


def swarm_key(network_key: bytes, master: int, session: int) -> bytes:
    """The key of the swarm ``master`` organizes in ``session``: derived with the network key, so only a holder of
    it can compute it, and the same in every run of a seed (model time stays a pure function of the seed)."""
    data = f"swarm/{master}/{session}".encode()
    return hashlib.blake2b(data, key=network_key, digest_size=16).digest()


@dataclass
class SecurityCounters:
    """What a node's link security did."""

    secured_sent: int = 0
    accepted: int = 0
    unsecured: int = 0
    mic_failed: int = 0
    replayed: int = 0
    unknown_key: int = 0
    malformed: int = 0

    def to_dict(self) -> dict[str, int]:
        """For a status answer."""
        return dict(self.__dict__)


@dataclass
class LinkSecurity:
    """One node's 802.15.4 security: its keys by index, its outgoing frame counter, and what it heard from whom."""

    network_key: bytes
    mic_len: int = 4
    keys: dict[int, bytes] = field(default_factory=dict)
    frame_counter: int = 0
    swarm_pan: int | None = None
    """The PAN of the swarm whose key this node holds (None: none)."""
    counters: SecurityCounters = field(default_factory=SecurityCounters)
    _expected: OrderedDict[tuple[int, int, int], int] = field(default_factory=OrderedDict)
    _ciphers: dict[bytes, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mic_len not in LEVELS:
            raise ValueError(f"the MIC is 4 or 8 bytes, not {self.mic_len}")
        if len(self.network_key) != 16:
            raise ValueError("the network key is 128 bits")
        self.keys[NETWORK_KEY] = self.network_key

    @property
    def overhead(self) -> int:
        """Bytes security adds to a frame's PSDU: the auxiliary security header and the MIC."""
        return AUX_LEN + self.mic_len

    def max_payload(self, pan_compressed: bool = True) -> int:
        """The largest payload a secured short-addressed data frame carries within 127 bytes."""
        return MAX_PSDU - FCS_LEN - (9 if pan_compressed else 11) - self.overhead

    def set_swarm_key(self, key: bytes | None, pan_id: int | None = None) -> None:
        """Use ``key`` (index 2) for the frames to the swarm's PAN ``pan_id``; None forgets it."""
        if key is None:
            self.keys.pop(SWARM_KEY, None)
            self.swarm_pan = None
        else:
            self.keys[SWARM_KEY] = bytes(key)
            self.swarm_pan = pan_id

    def key_for(self, frame: Frame) -> int:
        """The key index a frame goes under: the swarm's key on the swarm's PAN, the network key elsewhere."""
        return SWARM_KEY if self.swarm_pan is not None and frame.dst_pan == self.swarm_pan else NETWORK_KEY

    def protect_auto(self, frame: Frame) -> Frame:
        """``protect`` under the key ``key_for`` chooses."""
        return self.protect(frame, self.key_for(frame))

    def protect(self, frame: Frame, key_index: int = NETWORK_KEY) -> Frame:
        """``frame`` secured (a data or command frame; an ACK goes as it is). SecurityError when the frame counter
        is exhausted or the key is unknown."""
        if frame.frame_type is FrameType.ACK:
            return frame
        key = self.keys.get(key_index)
        if key is None:
            raise SecurityError("unknown_key", f"no key of index {key_index}")
        if self.frame_counter >= COUNTER_MAX:
            raise SecurityError("counter", "the frame counter is exhausted: a new network key is needed")
        counter, self.frame_counter = self.frame_counter, self.frame_counter + 1
        level = LEVELS[self.mic_len]
        aux = _AUX.pack(level | KEY_ID_MODE << 3, counter, key_index)
        secured = replace(frame, payload=aux, secured=True)
        header = secured.header()
        sealed = self._cipher(key).encrypt(_nonce(frame, counter, level), frame.payload, header)
        self.counters.secured_sent += 1
        return replace(secured, payload=aux + sealed)

    def unprotect(self, frame: Frame) -> Frame:
        """The plain frame of a secured one, after its MIC and frame counter are checked; a frame without
        security is refused. SecurityError (its ``reason`` counted) on anything refused."""
        try:
            plain = self._unprotect(frame)
        except SecurityError as err:
            setattr(self.counters, err.reason, getattr(self.counters, err.reason) + 1)
            raise
        self.counters.accepted += 1
        return plain

    def _unprotect(self, frame: Frame) -> Frame:
        if frame.frame_type is FrameType.ACK:
            return frame
        if not frame.secured:
            raise SecurityError("unsecured", "a frame without security where security is required")
        if len(frame.payload) < AUX_LEN:
            raise SecurityError("malformed", "no auxiliary security header")
        control, counter, key_index = _AUX.unpack_from(frame.payload)
        level, mode = control & 7, (control >> 3) & 3
        mic_len = MIC_OF_LEVEL.get(level)
        if mic_len is None or mode != KEY_ID_MODE or len(frame.payload) < AUX_LEN + mic_len:
            raise SecurityError("malformed", f"security level {level} with key identifier mode {mode}")
        key = self.keys.get(key_index)
        if key is None:
            raise SecurityError("unknown_key", f"no key of index {key_index}")
        sender = (key_index, frame.src_pan, frame.src)
        expected = self._expected.get(sender, 0)
        if counter < expected or counter >= COUNTER_MAX:
            raise SecurityError("replayed", f"frame counter {counter}, expected at least {expected}")
        aux, sealed = frame.payload[:AUX_LEN], frame.payload[AUX_LEN:]
        header = replace(frame, payload=aux).header()
        try:
            payload = self._cipher(key, mic_len).decrypt(_nonce(frame, counter, level), sealed, header)
        except Exception:  # cryptography's InvalidTag: imported lazily with the cipher
            raise SecurityError("mic_failed", "the MIC does not verify") from None
        # only an authentic frame moves the counter: a forged one must not lock the real sender out
        self._expected[sender] = counter + 1
        self._expected.move_to_end(sender)
        if len(self._expected) > SENDERS_KEPT:
            self._expected.popitem(last=False)
        return replace(frame, payload=payload, secured=False)

    def _cipher(self, key: bytes, mic_len: int | None = None) -> Any:
        mic = self.mic_len if mic_len is None else mic_len
        cipher = self._ciphers.get(key + bytes([mic]))
        if cipher is None:
            # imported here: a robot without link security never loads OpenSSL (cli/lean.py)
            from cryptography.hazmat.primitives.ciphers.aead import AESCCM

            cipher = self._ciphers[key + bytes([mic])] = AESCCM(key, tag_length=mic)
        return cipher


def _nonce(frame: Frame, counter: int, level: int) -> bytes:
    """The CCM* nonce: source address (here PAN ID, short address, 0xFFFFFFFF), frame counter, security level."""
    return _NONCE.pack(frame.src_pan, frame.src, 0xFFFFFFFF, counter, level)
