"""State codes shared by the core and the messages (ground layer).

Each enum's values ARE the constants of its message (``simreal_msgs/msg``), so a state goes into a message as
``int(state)`` and comes out as ``Enum(msg.state)`` with no table in between; ``tests/test_states.py`` checks
them against the generated messages. Two numberings exist because two messages do: a tracking node's
health (TrackingStatus.msg) and one object's parameter estimate (ModelParameters.msg). :class:`PointFlag` is the bit
layout of a PointCloud2 field, which has no message constants.
"""

from __future__ import annotations

from enum import IntEnum


class TrackingState(IntEnum):
    """TrackingStatus.msg STATE_*: the localization's (and a tracking node's) state."""

    NOT_STARTED = 0
    INITIALIZING = 1
    OK = 2
    LOST = 3
    RELOCALIZED = 4
    LOW_CONFIDENCE = 5


class PointFlag(IntEnum):
    """Bits of the ``flags`` field of ``/simreal/localization/deformable_points`` (PointCloud2): the tracker's word on
    each map point of a deforming object."""

    DROP = 1  # the last fit rejected this point: forget its image track
    HELD = 2  # linked in the object's rest shape (thesis §4.4: the scanned V_DP): the map keeps it


class EstimateState(IntEnum):
    """ModelParameters.msg STATE_*: how far one object's parameter estimate can be trusted."""

    OK = 0
    LOW_CONFIDENCE = 1
    LOST = 2
    INITIALIZING = 3


class ContactPhase(IntEnum):
    """ContactState.msg STATE_*: where Alg. 5.1 stands for one virtual object."""

    FREE = 0
    CONTACT = 1
    RELEASING = 2
    NO_DATA = 3


def tracking_state(estimate: EstimateState) -> TrackingState:
    """The TrackingStatus a deformable tracker reports for one object's estimate: the same word in the
    other numbering (every estimate state has a tracking state of that name)."""
    return TrackingState[EstimateState(estimate).name]
