"""ROS 2 action goals without I/O: status codes, cancel rules, goal ids (action_msgs semantics).

An action ``pkg/action/Name`` on ``<action>`` is, on the rmw_zenoh wire, three services and two
topics under ``<action>/_action/``: ``send_goal`` (``pkg/action/Name_SendGoal``),
``get_result`` (``Name_GetResult``), ``cancel_goal`` (``action_msgs/srv/CancelGoal``),
``feedback`` (``Name_FeedbackMessage``) and ``status`` (``action_msgs/msg/GoalStatusArray``).
Goals are named by a 16-byte UUID the client chooses.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from dataclasses import dataclass
from enum import IntEnum

CANCEL_TYPE = "action_msgs/srv/CancelGoal"
STATUS_TYPE = "action_msgs/msg/GoalStatusArray"
UUID_TYPE = "unique_identifier_msgs/msg/UUID"
GOAL_ID_SIZE = 16


class GoalStatus(IntEnum):
    """``action_msgs/msg/GoalStatus`` constants."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6

    @property
    def label(self) -> str:
        """The status name in lower case (``succeeded``)."""
        return self.name.lower()

    @property
    def terminal(self) -> bool:
        """Whether the goal has finished: SUCCEEDED, CANCELED or ABORTED."""
        return self in TERMINAL


TERMINAL = frozenset({GoalStatus.SUCCEEDED, GoalStatus.CANCELED, GoalStatus.ABORTED})
CANCELABLE = frozenset({GoalStatus.ACCEPTED, GoalStatus.EXECUTING})


class CancelCode(IntEnum):
    """``action_msgs/srv/CancelGoal`` response return codes."""

    ERROR_NONE = 0
    ERROR_REJECTED = 1
    ERROR_UNKNOWN_GOAL_ID = 2
    ERROR_GOAL_TERMINATED = 3

    @property
    def meaning(self) -> str:
        """A sentence saying what the code means for the cancel request."""
        return _CANCEL_MEANING[self]


_CANCEL_MEANING = {
    CancelCode.ERROR_NONE: "the goal is being canceled",
    CancelCode.ERROR_REJECTED: "the action server rejected the cancel request",
    CancelCode.ERROR_UNKNOWN_GOAL_ID: "the action server does not know the goal",
    CancelCode.ERROR_GOAL_TERMINATED: "the goal had already finished",
}


def status_label(code: int) -> str:
    """``4`` -> ``succeeded``; an unknown code -> ``status <n>``."""
    try:
        return GoalStatus(code).label
    except ValueError:
        return f"status {code}"


@dataclass(frozen=True, slots=True)
class CancelDecision:
    """A cancel request's answer: the return code and the ids of the goals now canceling."""

    code: CancelCode
    canceling: tuple[bytes, ...]


ZERO_ID = bytes(GOAL_ID_SIZE)


def decide_cancel(
    goals: Mapping[bytes, GoalStatus], goal_id: bytes, stamp_ns: int, accepted_ns: Mapping[bytes, int]
) -> CancelDecision:
    """What an action server answers a cancel request (rcl_action's rules).

    A zero goal id with a zero stamp cancels every cancelable goal; a zero id with a stamp those
    accepted at or before it; a goal id that goal (and, with a stamp, also the earlier ones).
    Nothing cancelable: ``ERROR_UNKNOWN_GOAL_ID`` when the named goal is not known,
    ``ERROR_GOAL_TERMINATED`` when it has finished, else ``ERROR_REJECTED``.
    """
    chosen: list[bytes] = []
    if goal_id != ZERO_ID:
        status = goals.get(goal_id)
        if status is not None and status in CANCELABLE:
            chosen.append(goal_id)
    if goal_id == ZERO_ID or stamp_ns > 0:
        for other, status in goals.items():
            if other in chosen or status not in CANCELABLE:
                continue
            if (goal_id == ZERO_ID and stamp_ns == 0) or accepted_ns.get(other, 0) <= stamp_ns:
                chosen.append(other)
    if chosen:
        return CancelDecision(CancelCode.ERROR_NONE, tuple(chosen))
    if goal_id != ZERO_ID:
        status = goals.get(goal_id)
        if status is None:
            return CancelDecision(CancelCode.ERROR_UNKNOWN_GOAL_ID, ())
        if status in TERMINAL:
            return CancelDecision(CancelCode.ERROR_GOAL_TERMINATED, ())
    return CancelDecision(CancelCode.ERROR_REJECTED, ())


def goal_id_bytes(text: str) -> bytes:
    """A goal id from its text form (a UUID, with or without dashes); ``ValueError`` otherwise."""
    return uuid.UUID(text.strip()).bytes


def goal_id_text(raw: bytes) -> str:
    """The canonical text of a 16-byte goal id (``8-4-4-4-12`` hex)."""
    if len(raw) != GOAL_ID_SIZE:
        raise ValueError(f"a goal id has {GOAL_ID_SIZE} bytes, got {len(raw)}")
    return str(uuid.UUID(bytes=raw))


def action_part(action: str, part: str) -> str:
    """``/tb4_01/dock``, ``send_goal`` -> ``/tb4_01/dock/_action/send_goal``."""
    return f"{action.rstrip('/')}/_action/{part}"
