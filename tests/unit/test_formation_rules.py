"""Tables 1 and 2, the PAN choice, answer slots, two masters of one swarm and the robot state machine."""

import numpy as np
import pytest

from petswarm.managers.decisions import (
    SWARM_PANS,
    Rival,
    choose_pan,
    may_join,
    reply_delay_s,
    rival_master,
    select_members,
)
from petswarm.managers.event_log import EventLog
from petswarm.managers.messages import Refusal
from petswarm.managers.sequence import RobotState, SequenceManager, TransitionError


@pytest.mark.parametrize(
    "user, rssi, expected",
    [
        (0, -60, None),  # not connected, inside: can join
        (0, -80, Refusal.OUTSIDE_REGION),  # not connected, outside: cannot
        (2, -60, Refusal.CONNECTED_TO_USER),  # connected to another user: cannot
        (2, -80, Refusal.CONNECTED_TO_USER),  # connection is checked before the region
    ],
)
def test_table_1(user, rssi, expected):
    assert may_join(user, rssi, -70) == expected


def test_table_1_region_edge_is_inside():
    assert may_join(0, -70, -70) is None


def test_table_2_closest_first_when_more_are_available():
    available = {5: -60.0, 6: -45.0, 7: -52.0, 8: -71.0}
    assert select_members(available, 2) == [6, 7]


def test_table_2_all_when_not_more_are_available():
    available = {5: -60.0, 6: -45.0}
    assert sorted(select_members(available, 2)) == [5, 6]
    assert sorted(select_members(available, 8)) == [5, 6]


def test_table_2_ties_go_to_the_lower_address():
    assert select_members({9: -50.0, 4: -50.0, 7: -50.0}, 2) == [4, 7]


def test_pan_choice_avoids_every_pan_in_use_and_is_reproducible():
    used = set(range(SWARM_PANS.start, SWARM_PANS.stop - 3))  # only three free swarm PANs left
    pan = choose_pan(np.random.default_rng(1), used)
    assert pan not in used and pan in SWARM_PANS
    assert choose_pan(np.random.default_rng(9), ()) == choose_pan(np.random.default_rng(9), ())


def test_answer_slots():
    assert reply_delay_s(5, 0, (3, 5)) == 0.0  # the paper's protocol answers at once
    assert reply_delay_s(5, 4, (3, 5)) == pytest.approx(0.004)  # second in the pending list
    assert reply_delay_s(3, 4, (3, 5)) == 0.0
    assert reply_delay_s(10, 4) == pytest.approx(0.008)  # not listed: address modulo 8 slots
    delays = {reply_delay_s(a, 4, (2, 3, 4, 5, 6)) for a in (2, 3, 4, 5, 6)}
    assert len(delays) == 5  # nobody shares a slot


def test_states_follow_fig_4_and_record_every_transition():
    log = EventLog()
    seq = SequenceManager(log, RobotState.LEADING)
    seq.transition(RobotState.ORGANIZING, session=7)
    seq.transition(RobotState.MASTER_DRIVING)
    assert seq.restore_driving() == RobotState.LEADING  # the previous driving state comes back
    assert [(e["frm"], e["to"]) for e in log.events] == [
        ("leading", "organizing"),
        ("organizing", "master-driving"),
        ("master-driving", "leading"),
    ]
    assert log.events[0]["session"] == 7 and log.events[0]["t"] <= log.events[-1]["t"]


def test_impossible_transitions_are_refused():
    seq = SequenceManager(EventLog())
    with pytest.raises(TransitionError):
        seq.transition(RobotState.SLAVE_DRIVING)  # waiting -> slave needs organizing first
    seq.transition(RobotState.ORGANIZING)
    seq.transition(RobotState.SLAVE_DRIVING)
    with pytest.raises(TransitionError):
        seq.transition(RobotState.FOLLOWING)  # a slave drives with no user of its own
    assert not seq.user_connected


def test_the_master_role_passes_between_slave_and_master_driving():
    # Table 3's Change column: a slave takes over as master, the old master becomes a slave
    seq = SequenceManager(EventLog())
    seq.transition(RobotState.ORGANIZING)
    seq.transition(RobotState.SLAVE_DRIVING)
    seq.transition(RobotState.MASTER_DRIVING, cause="handover")
    assert seq.user_connected
    seq.transition(RobotState.SLAVE_DRIVING, cause="handover")
    assert not seq.user_connected


def test_a_former_master_that_became_a_candidate_has_no_user_and_no_driving_state_to_return_to():
    seq = SequenceManager(EventLog(), RobotState.FOLLOWING)
    seq.transition(RobotState.ORGANIZING)
    seq.transition(RobotState.MASTER_DRIVING)
    seq.transition(RobotState.SLAVE_DRIVING, cause="handover")
    seq.transition(RobotState.WAITING, reason="dispersed")
    seq.transition(RobotState.ORGANIZING, master=9)  # said 'available' to another master
    assert not seq.user_connected
    assert seq.previous_driving is None


def test_the_largest_roster_and_query_fit_one_inter_pan_frame():
    from petswarm.managers.formation import MAX_LISTED, MAX_MEMBERS
    from petswarm.managers.messages import JoinNotice, JoinQuery, Roster, Scan, ScanReply
    from radio_hub.air.mac import max_payload

    worst = 0xFFFD  # short addresses of three msgpack bytes
    limit = max_payload(pan_compressed=False)
    assert len(Roster(0xFFFF, (worst,) * MAX_MEMBERS).encode()) <= limit
    assert len(JoinQuery(0xFFFF, 0xFFFF, -120, 255, (worst,) * MAX_LISTED).encode()) <= limit
    for msg in (
        Scan(0xFFFF, 0xFFFF, 255),
        ScanReply(0xFFFF, 7, 0xFFFF, 0xFFFF),
        JoinNotice(0xFFFF, 0xFFFF, 33, 32, 255),
    ):
        assert len(msg.encode()) <= limit


def test_a_handover_of_a_16_robot_swarm_fits_one_inter_pan_frame():
    from petswarm.managers.messages import DriveState, MasterHandover, decode
    from radio_hub.air.mac import max_payload

    msg = MasterHandover(0xFFFF, 0xFFFF, (0xFFFD,) * 16, "following", "column", 0.6, 1, 1, "user-someone")
    assert len(msg.encode()) <= max_payload(pan_compressed=False) and decode(msg.encode()) == msg
    state = DriveState(0xFFFF, 0xFFFF, 0.1, 0.1, 0.1, 3.1, 2, 0.5, "following", "column", 0.6, 1.2, 0.1, 1, 1)
    assert len(state.encode()) <= max_payload(pan_compressed=False)


def test_a_master_follows_the_target_of_its_unaccepted_handover_whatever_the_addresses():
    # robot 1 handed over to 3, the acceptance was lost; 3's roster says it took the role
    assert rival_master(1, 3, (2, 3), set(), handed_to=3, listed=True) is Rival.FOLLOW
    # also when 1 already stopped counting 3 (it missed 3's answers meanwhile), or 3 does not count 1
    assert rival_master(1, 3, (2,), set(), handed_to=3, listed=False) is Rival.FOLLOW
    # another robot's roster is judged by the general rule, not taken as the handover
    assert rival_master(5, 2, (2, 3), set(), handed_to=3, listed=True) is Rival.YIELD


def test_a_master_ignores_its_own_rosters_former_masters_and_strangers():
    assert rival_master(4, 4, (2, 3), set(), None, True) is Rival.IGNORE
    assert rival_master(4, 1, (2, 3, 1), {1}, None, True) is Rival.IGNORE  # a late roster of a former master
    assert rival_master(4, 1, (2, 3), set(), None, True) is Rival.IGNORE  # not a robot of this swarm


def test_of_two_masters_exactly_one_yields_the_lower_address_keeps_the_role():
    for a, b in ((2, 7), (7, 2), (0x10, 0xFFFD)):
        verdicts = {rival_master(a, b, (b, 9), set(), None, True), rival_master(b, a, (a, 9), set(), None, True)}
        assert verdicts == {Rival.KEEP, Rival.YIELD}, (a, b)
        assert rival_master(max(a, b), min(a, b), (min(a, b),), set(), None, True) is Rival.YIELD


def test_an_outranked_master_that_the_rival_does_not_count_leaves_the_swarm():
    assert rival_master(7, 2, (2, 3), set(), None, listed=False) is Rival.LEAVE
    assert rival_master(2, 7, (7, 3), set(), None, listed=False) is Rival.KEEP
