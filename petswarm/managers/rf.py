"""RF communication manager: swarm messages over the robot's 802.15.4 radio."""

from __future__ import annotations

import asyncio
import dataclasses
from collections import Counter

from petswarm import clock
from petswarm.managers.actions import Incoming
from petswarm.managers.messages import JoinNotice, MessageError, SwarmMessage, decode
from petswarm.managers.serial_link import SerialLink
from radio_hub.interface import RadioClient, swarm_key
from radio_hub.values import BROADCAST, TxResult


class RfCommunicationManager:
    """Sends and receives swarm messages; counts what it could not understand and how sends ended.

    With a ``link`` (a profile's MCU and UART) every frame waits on the loop's clock until the link has
    passed it, both ways; without one (the ideal robot) nothing waits."""

    def __init__(self, radio: RadioClient, link: SerialLink | None = None) -> None:
        self.radio = radio
        self.link = link
        self.tx_results: Counter[str] = Counter()
        self.received = 0
        self.malformed = 0

    async def send(self, dst: int, message: SwarmMessage, *, dst_pan: int | None = None, ack: bool = True) -> TxResult:
        """Send one message in one frame; unicast is acknowledged unless ``ack`` is False. With link security a
        join notice carries the swarm's key (the master uses it from now on for the swarm's PAN)."""
        security = self.radio.security
        if security is not None and isinstance(message, JoinNotice):
            key = swarm_key(security.network_key, self.radio.identity.short_addr, message.session)
            security.set_swarm_key(key, message.pan_id)
            message = dataclasses.replace(message, key=key)
        payload = message.encode()
        if self.link is not None:
            await _until(self.link.tx_ready(clock.now(), len(payload)))
        frame = self.radio.data_frame(dst, payload, dst_pan=dst_pan, ack=ack and dst != BROADCAST)
        result = await self.radio.send(frame)
        self.tx_results[result.status.value] += 1
        return result

    async def receive(self) -> Incoming:
        """The next frame that carries a valid message; anything else is counted and skipped."""
        while True:
            rx = await self.radio.receive()
            if self.link is not None:
                await _until(self.link.rx_ready(clock.now(), len(rx.frame.payload)))
            try:
                message = decode(rx.frame.payload)
            except MessageError:
                self.malformed += 1
                continue
            except Exception as err:  # a decoder bug must not stop the robot hearing the next frame
                self.malformed += 1
                self.radio.faults.record("swarm message", err)
                continue
            self.received += 1
            security = self.radio.security
            if security is not None and isinstance(message, JoinNotice) and len(message.key) == 16:
                # the join handshake: the notice came secured under the network key, so from a key holder
                security.set_swarm_key(message.key, message.pan_id)
            return Incoming(message, rx, clock.now())


async def _until(when: float) -> None:
    """Wait on the loop's clock until ``when`` (seconds)."""
    await asyncio.sleep(max(when - clock.now(), 0.0))
