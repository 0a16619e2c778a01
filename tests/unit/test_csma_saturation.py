"""Unslotted CSMA-CA under saturation: the medium against an independent Monte Carlo written here.

N senders around a sink, all in one carrier-sense domain, each with a frame always waiting (61-octet MPDUs, no
ACK). Per sender and frame: the interframe spacing after its last frame (LIFS), then NB = 0, BE = macMinBE;
backoff of random(2^BE) unit periods; CCA over 8 symbols; busy -> NB + 1, BE + 1 up to macMaxBE, give up after
macMaxCSMABackoffs + 1 busy CCAs; clear -> turnaround, then the frame (IEEE 802.15.4-2011 5.1.1.4). The Monte
Carlo below is that paragraph and nothing else: its own event loop and its own generator. Throughput (the share
of time carrying a frame no other overlaps) and collision probability (the share of frames another overlaps)
come out of both the same way, from the frames' air times.
"""

from __future__ import annotations

import heapq
import math
import random
import statistics

import numpy as np
import pytest

from radio_hub.air.medium import Medium, TxReport
from radio_hub.config import MediumConfig, airtime_us

from .helpers import data, place

UNIT, CCA, TURNAROUND, LIFS = 320, 128, 192, 640
MIN_BE, MAX_BE, MAX_BACKOFFS = 3, 5, 4
PAYLOAD = 50
DURATION_US = 1_000_000
SEEDS = 8


def _metrics(spans: list[tuple[int, int]]) -> tuple[float, float]:
    """(throughput, collision probability) of frames on one shared channel."""
    spans = sorted(spans)
    clean = 0
    busy_us = 0
    for i, (start, end) in enumerate(spans):
        neighbours = spans[max(0, i - 40) : i] + spans[i + 1 : i + 40]
        if not any(s < end and e > start for s, e in neighbours):
            clean += 1
            busy_us += end - start
    return busy_us / DURATION_US, 1 - clean / len(spans)


def _medium_run(n: int, seed: int) -> tuple[float, float]:
    config = MediumConfig.from_dict(
        {"range": {"success_ratio_rx": 1.0}, "path_loss": {"shadowing_sigma_db": 0.0}, "mac": {"ack_enabled": False}}
    )
    spans: list[tuple[int, int]] = []
    m = Medium(config, np.random.default_rng(seed), on_air_end=lambda tx: spans.append((tx.start_us, tx.end_us)))
    senders = [place(m, i + 1, math.cos(2 * math.pi * i / n), math.sin(2 * math.pi * i / n)) for i in range(n)]
    place(m, 1000, 0.0, 0.0)
    psdus = {node: data(i + 1, payload=bytes(PAYLOAD), ack=False) for i, node in enumerate(senders)}
    work = [out for node in senders for out in m.submit(node, psdus[node], 0, 0)]
    while True:
        for out in work:
            if isinstance(out, TxReport) and out.done_us < DURATION_US:
                work.extend(m.submit(out.node_id, psdus[out.node_id], 0, out.done_us))
        t = m.next_event_us()
        if t is None or t >= DURATION_US:
            break
        work = m.advance(t)
    return _metrics([s for s in spans if s[1] <= DURATION_US])


def _monte_carlo(n: int, seed: int, airtime: int) -> tuple[float, float]:
    rng = random.Random(seed)
    spans: list[tuple[int, int]] = []
    events: list[tuple[int, int, str, int, int]] = []
    nb, be = [0] * n, [0] * n
    order = 0

    def at(t: int, kind: str, who: int, extra: int = 0) -> None:
        nonlocal order
        order += 1
        heapq.heappush(events, (t, order, kind, who, extra))

    def backoff(who: int, t: int) -> None:
        cca_start = t + rng.randrange(1 << be[who]) * UNIT
        at(cca_start + CCA, "cca", who, cca_start)

    def begin(who: int, t: int) -> None:
        nb[who], be[who] = 0, MIN_BE
        backoff(who, t)

    for who in range(n):
        begin(who, 0)
    while events:
        t, _, kind, who, extra = heapq.heappop(events)
        if t >= DURATION_US:
            break
        if kind == "cca":
            if not any(s < t and e > extra for s, e in spans[-n:]):
                at(t + TURNAROUND, "tx", who)
                continue
            nb[who] += 1
            be[who] = min(be[who] + 1, MAX_BE)
            if nb[who] > MAX_BACKOFFS:
                begin(who, t)  # channel access failure: the next frame, no frame was sent so no IFS
            else:
                backoff(who, t)
        elif kind == "tx":
            spans.append((t, t + airtime))
            begin(who, t + airtime + LIFS)
    return _metrics([s for s in spans if s[1] <= DURATION_US])


@pytest.mark.parametrize("n", [1, 2, 5, 10, 20])
def test_saturation_throughput_and_collisions_match_the_monte_carlo(n: int) -> None:
    airtime = airtime_us(len(data(1, payload=bytes(PAYLOAD), ack=False)))
    ours = [_medium_run(n, seed) for seed in range(SEEDS)]
    theirs = [_monte_carlo(n, 1000 + seed, airtime) for seed in range(SEEDS)]
    for k, name in enumerate(("throughput", "collision probability")):
        a, b = [r[k] for r in ours], [r[k] for r in theirs]
        spread = math.sqrt((statistics.pvariance(a) + statistics.pvariance(b)) / SEEDS)
        assert abs(statistics.mean(a) - statistics.mean(b)) <= 4 * spread, (name, a, b)
    if n == 1:
        # one sender: a frame every LIFS + mean backoff (3.5 units) + CCA + turnaround + airtime
        cycle = LIFS + 3.5 * UNIT + CCA + TURNAROUND + airtime
        assert statistics.mean(r[0] for r in ours) == pytest.approx(airtime / cycle, rel=0.02)
