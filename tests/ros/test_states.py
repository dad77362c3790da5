"""The state enums of simreal_nodes.states are the message constants: every member equals the generated
STATE_* constant of the same name, and every STATE_* constant has a member."""

from __future__ import annotations

from enum import IntEnum

import pytest

pytest.importorskip("rclpy")

from simreal_msgs.msg import ContactState, ModelParameters, TrackingStatus

from simreal_nodes.states import (
    ContactPhase,
    EstimateState,
    TrackingState,
    tracking_state,
)


@pytest.mark.parametrize("enum, msg", [(TrackingState, TrackingStatus), (EstimateState, ModelParameters),
                                       (ContactPhase, ContactState)])
def test_enum_members_are_the_message_constants(enum: type[IntEnum], msg: type) -> None:
    constants = {name[len("STATE_"):]: getattr(msg, name) for name in dir(msg) if name.startswith("STATE_")}
    assert {m.name: int(m) for m in enum} == constants


def test_an_estimate_state_reports_the_tracking_state_of_its_name() -> None:
    for s in EstimateState:
        assert tracking_state(s).name == s.name
        assert int(tracking_state(s)) == getattr(TrackingStatus, f"STATE_{s.name}")
