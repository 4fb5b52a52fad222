"""ROS 2 actions on the rmw_zenoh wire: an action server and an action client.

An action is three services and two topics under ``<action>/_action/``
(:mod:`roswire.action_goals`); both sides here are made of :mod:`roswire.service` servers and
clients and rmw_zenoh publishers and subscribers, so every step is a real Zenoh query or sample:

* :class:`RosActionServer` accepts goals (``send_goal``), runs each in a thread of its own
  (``execute(handle)``), publishes feedback and the status array (TRANSIENT_LOCAL, as rclcpp's
  status publisher), answers ``get_result`` when the goal has finished (a request for a running
  goal waits) and ``cancel_goal`` by rcl_action's rules; results are kept ``result_timeout``
  seconds after the goal finished.
* :class:`RosActionClient` sends goals, waits for results, cancels, and hands each goal's
  feedback to the listener registered for its id. Messages travel as CDR; the client composes
  and splits the action's wrapper messages (``SendGoal_Request`` = goal id + goal …) itself.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from fleetlink.roswire.action_goals import (
    CANCEL_TYPE,
    GOAL_ID_SIZE,
    STATUS_TYPE,
    UUID_TYPE,
    CancelCode,
    GoalStatus,
    action_part,
    decide_cancel,
)
from fleetlink.roswire.errors import RoswireError
from fleetlink.roswire.qos import DEFAULT, TRANSIENT_LOCAL
from fleetlink.roswire.service import RosServiceClient, RosServiceServer, ServiceCall
from fleetlink.roswire.subscriber import RosSample, RosSubscriber

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from fleetlink.roswire.node import RosNode
    from fleetlink.roswire.publisher import RosPublisher

log = logging.getLogger(__name__)

RESULT_TIMEOUT_S = 900.0
"""How long a finished goal's result is kept (rclcpp's default: 15 minutes)."""


def _typestore(node: RosNode) -> Typestore:
    ts = node.typestore
    if ts is None:
        raise RoswireError(f"node {node.name!r}: actions need a node with a type store")
    return ts


def _uuid(ts: Typestore, goal_id: bytes) -> Any:
    return ts.types[UUID_TYPE](uuid=np.frombuffer(goal_id, dtype=np.uint8).copy())


def _time(ts: Typestore, ns: int) -> Any:
    return ts.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _decode(ts: Typestore, raw: bytes, typename: str) -> Any:
    return ts.deserialize_cdr(raw, typename)


def _ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def default_message(ts: Typestore, typename: str) -> Any:
    """A message of ``typename`` with every field at its default."""
    from fleetlink.schemas.messages import from_data

    return from_data(ts, typename, {})


# -- server -----------------------------------------------------------------------------------


@dataclass(eq=False)
class GoalHandle:
    """One goal on the server side; ``execute`` reads ``goal``, publishes feedback, and watches
    ``cancel_requested``; what it returns is the result (or it calls :meth:`finish`)."""

    server: RosActionServer
    goal_id: bytes
    goal: Any
    accepted_ns: int
    status: GoalStatus = GoalStatus.ACCEPTED
    result: Any = None
    finished_at: float = 0.0
    cancel_requested: threading.Event = field(default_factory=threading.Event)
    waiters: list[ServiceCall] = field(default_factory=list)

    def publish_feedback(self, feedback: Any) -> None:
        """Publish ``feedback`` (a ``Name_Feedback`` message) for this goal."""
        self.server.publish_feedback(self, feedback)

    def finish(self, status: GoalStatus, result: Any = None) -> None:
        """End the goal as SUCCEEDED, CANCELED or ABORTED (later calls change nothing)."""
        self.server.finish(self, status, result)


Execute = Callable[[GoalHandle], Any]
"""Runs one goal; returns its result (SUCCEEDED, or CANCELED when a cancel was requested)."""
Accept = Callable[[Any], bool]


class RosActionServer:
    """Serves one ROS 2 action: accepts goals, runs each in its own thread, publishes feedback and status."""

    def __init__(
        self,
        node: RosNode,
        action: str,
        typename: str,
        execute: Execute,
        *,
        accept: Accept = lambda _goal: True,
        result_timeout: float = RESULT_TIMEOUT_S,
    ) -> None:
        self.node = node
        self.action = node.resolve(action)
        self.typename = typename
        self._execute = execute
        self._accept = accept
        self.result_timeout = result_timeout
        self._ts = _typestore(node)
        self._lock = threading.RLock()
        self._goals: dict[bytes, GoalHandle] = {}
        self._services: list[RosServiceServer] = []
        self._feedback: RosPublisher | None = None
        self._status: RosPublisher | None = None
        self.goals_received = 0

    def start(self) -> RosActionServer:
        """Declare the feedback and status publishers and the three services; returns self."""
        if self._services:
            return self
        node, t = self.node, self.typename
        self._feedback = node.create_publisher(action_part(self.action, "feedback"), f"{t}_FeedbackMessage")
        self._status = node.create_publisher(action_part(self.action, "status"), STATUS_TYPE, TRANSIENT_LOCAL)
        for part, typename, handler in (
            ("send_goal", f"{t}_SendGoal", self._on_send_goal),
            ("cancel_goal", CANCEL_TYPE, self._on_cancel),
            ("get_result", f"{t}_GetResult", self._on_get_result),
        ):
            server = RosServiceServer(node, action_part(self.action, part), typename, handler)
            self._services.append(server.start())
        return self

    def stop(self) -> None:
        """Undeclare the services and publishers and ask every running goal to cancel."""
        for server in self._services:
            server.stop()
        self._services = []
        for pub in (self._feedback, self._status):
            if pub is not None:
                pub.stop()
        self._feedback = self._status = None
        with self._lock:
            handles = list(self._goals.values())
        for handle in handles:
            handle.cancel_requested.set()

    def goals(self) -> dict[bytes, GoalStatus]:
        """Goal id -> status of every goal still known (finished ones until their result expires)."""
        with self._lock:
            return {gid: h.status for gid, h in self._goals.items()}

    # -- services -----------------------------------------------------------------------------

    def _on_send_goal(self, call: ServiceCall) -> bytes:
        ts, t = self._ts, self.typename
        request = _decode(ts, call.payload, f"{t}_SendGoal_Request")
        goal_id = bytes(np.asarray(request.goal_id.uuid, dtype=np.uint8).tobytes())
        now = time.time_ns()
        self.goals_received += 1
        try:
            accepted = bool(self._accept(request.goal))
        except Exception as exc:  # noqa: BLE001 - a failing accept callback rejects the goal
            log.warning("action %s: accept failed: %r", self.action, exc)
            accepted = False
        with self._lock:
            self._expire(time.monotonic())
            if goal_id in self._goals:
                accepted = False  # a goal id is used once
            handle = GoalHandle(self, goal_id, request.goal, now)
            if accepted:
                self._goals[goal_id] = handle
        response = ts.types[f"{t}_SendGoal_Response"](accepted=accepted, stamp=_time(ts, now))
        if accepted:
            self._publish_status()
            threading.Thread(target=self._run, args=(handle,), daemon=True, name=f"goal{self.action}").start()
        return bytes(ts.serialize_cdr(response, f"{t}_SendGoal_Response"))

    def _run(self, handle: GoalHandle) -> None:
        with self._lock:
            if handle.status is GoalStatus.ACCEPTED:
                handle.status = GoalStatus.EXECUTING
        self._publish_status()
        try:
            result = self._execute(handle)
        except Exception as exc:  # noqa: BLE001 - the goal aborts, the server lives on
            log.warning("action %s: goal failed: %r", self.action, exc)
            self.finish(handle, GoalStatus.ABORTED, None)
            return
        status = GoalStatus.CANCELED if handle.cancel_requested.is_set() else GoalStatus.SUCCEEDED
        self.finish(handle, status, result)

    def finish(self, handle: GoalHandle, status: GoalStatus, result: Any) -> None:
        """End a goal with a terminal status and result; publish the status and answer waiting results.

        Waiting results are the ``get_result`` calls made while the goal ran. A goal already finished
        is left as it is; a status that is not terminal raises ``RoswireError``; a None result becomes
        a default ``Name_Result``.
        """
        if not status.terminal:
            raise RoswireError(f"goal status {status.label} does not end a goal")
        with self._lock:
            if handle.status.terminal:
                return
            handle.status = status
            handle.result = (
                result if result is not None else default_message(self._ts, f"{self.typename}_Result")
            )
            handle.finished_at = time.monotonic()
            waiters, handle.waiters = handle.waiters, []
        self._publish_status()
        payload = self._result_cdr(handle)
        for call in waiters:
            call.reply(payload)

    def _result_cdr(self, handle: GoalHandle | None) -> bytes:
        ts, t = self._ts, self.typename
        if handle is None:
            status, result = GoalStatus.UNKNOWN, default_message(ts, f"{t}_Result")
        else:
            status, result = handle.status, handle.result
        response = ts.types[f"{t}_GetResult_Response"](status=int(status), result=result)
        return bytes(ts.serialize_cdr(response, f"{t}_GetResult_Response"))

    def _on_get_result(self, call: ServiceCall) -> bytes | None:
        request = _decode(self._ts, call.payload, f"{self.typename}_GetResult_Request")
        goal_id = bytes(np.asarray(request.goal_id.uuid, dtype=np.uint8).tobytes())
        with self._lock:
            handle = self._goals.get(goal_id)
            if handle is not None and not handle.status.terminal:
                handle.waiters.append(call)
                return None  # answered when the goal finishes
        return self._result_cdr(handle)

    def _on_cancel(self, call: ServiceCall) -> bytes:
        ts = self._ts
        request = _decode(ts, call.payload, f"{CANCEL_TYPE}_Request")
        goal_id = bytes(np.asarray(request.goal_info.goal_id.uuid, dtype=np.uint8).tobytes())
        with self._lock:
            self._expire(time.monotonic())
            decision = decide_cancel(
                {gid: h.status for gid, h in self._goals.items()},
                goal_id,
                _ns(request.goal_info.stamp),
                {gid: h.accepted_ns for gid, h in self._goals.items()},
            )
            infos = []
            for gid in decision.canceling:
                handle = self._goals[gid]
                handle.status = GoalStatus.CANCELING
                handle.cancel_requested.set()
                infos.append(
                    ts.types["action_msgs/msg/GoalInfo"](
                        goal_id=_uuid(ts, gid), stamp=_time(ts, handle.accepted_ns)
                    )
                )
        if decision.canceling:
            self._publish_status()
        response = ts.types[f"{CANCEL_TYPE}_Response"](return_code=int(decision.code), goals_canceling=infos)
        return bytes(ts.serialize_cdr(response, f"{CANCEL_TYPE}_Response"))

    # -- topics -------------------------------------------------------------------------------

    def publish_feedback(self, handle: GoalHandle, feedback: Any) -> None:
        """Publish ``feedback`` for the goal of ``handle`` (nothing once the server is stopped)."""
        ts, t = self._ts, self.typename
        pub = self._feedback
        if pub is None:
            return
        message = ts.types[f"{t}_FeedbackMessage"](goal_id=_uuid(ts, handle.goal_id), feedback=feedback)
        pub.publish(message)

    def _publish_status(self) -> None:
        ts = self._ts
        pub = self._status
        if pub is None:
            return
        with self._lock:
            entries = [
                ts.types["action_msgs/msg/GoalStatus"](
                    goal_info=ts.types["action_msgs/msg/GoalInfo"](
                        goal_id=_uuid(ts, h.goal_id), stamp=_time(ts, h.accepted_ns)
                    ),
                    status=int(h.status),
                )
                for h in self._goals.values()
            ]
        pub.publish(ts.types[STATUS_TYPE](status_list=entries))

    def _expire(self, now: float) -> None:
        for gid, handle in list(self._goals.items()):
            if handle.status.terminal and now - handle.finished_at > self.result_timeout:
                del self._goals[gid]


# -- client -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class GoalResponse:
    """The server's answer to a goal: accepted or not, and its stamp (Unix ns)."""

    accepted: bool
    stamp_ns: int


@dataclass(frozen=True, slots=True)
class ResultResponse:
    """A goal's final status (a plain int when unknown) and its result as ``Name_Result`` CDR."""

    status: GoalStatus | int
    result_cdr: bytes


@dataclass(frozen=True, slots=True)
class CancelResponse:
    """A cancel request's return code (a plain int when unknown) and the ids of the goals canceling."""

    code: CancelCode | int
    canceling: tuple[bytes, ...]


FeedbackListener = Callable[[bytes], object]
"""Gets each feedback of one goal as the CDR of ``pkg/action/Name_Feedback``."""


class RosActionClient:
    """Calls one ROS 2 action: sends goals, waits for results, cancels, and routes feedback per goal."""

    def __init__(self, node: RosNode, action: str, typename: str) -> None:
        self.node = node
        self.action = node.resolve(action)
        self.typename = typename
        self._ts = _typestore(node)
        self.send_goal_client = RosServiceClient(
            node, action_part(self.action, "send_goal"), f"{typename}_SendGoal"
        )
        self.get_result_client = RosServiceClient(
            node, action_part(self.action, "get_result"), f"{typename}_GetResult"
        )
        self.cancel_client = RosServiceClient(node, action_part(self.action, "cancel_goal"), CANCEL_TYPE)
        self._feedback_sub: RosSubscriber | None = None
        self._listeners: dict[bytes, FeedbackListener] = {}
        self._lock = threading.Lock()
        self.feedback_received = 0

    def start(self) -> RosActionClient:
        """Start the three service clients and subscribe to the feedback topic; returns self."""
        if self._feedback_sub is not None:
            return self
        for client in (self.send_goal_client, self.get_result_client, self.cancel_client):
            client.start()
        self._feedback_sub = RosSubscriber(
            self.node,
            action_part(self.action, "feedback"),
            f"{self.typename}_FeedbackMessage",
            self._on_feedback,
            DEFAULT,
        ).start()
        return self

    def stop(self) -> None:
        """Unsubscribe from feedback and stop the service clients."""
        if self._feedback_sub is not None:
            self._feedback_sub.stop()
            self._feedback_sub = None
        for client in (self.send_goal_client, self.get_result_client, self.cancel_client):
            client.stop()

    def server_available(self, timeout: float = 1.0) -> bool:
        """Whether an action server's ``send_goal`` service is announced (waits up to ``timeout`` s)."""
        return self.send_goal_client.server_available(timeout)

    def wait_for_server(self, timeout: float, *, stop: threading.Event | None = None) -> bool:
        """Wait until an action server is announced (at most ``timeout`` s, or until ``stop`` is set)."""
        return self.send_goal_client.wait_for_server(timeout, stop=stop)

    def listen(self, goal_id: bytes, listener: FeedbackListener | None) -> None:
        """Hand the feedback of ``goal_id`` to ``listener`` (None: stop)."""
        with self._lock:
            if listener is None:
                self._listeners.pop(goal_id, None)
            else:
                self._listeners[goal_id] = listener

    def send_goal(self, goal_id: bytes, goal_cdr: bytes, timeout: float) -> GoalResponse:
        """Send a goal (its ``Name_Goal`` CDR) under ``goal_id``; raises ``ServiceError``."""
        ts, t = self._ts, self.typename
        if len(goal_id) != GOAL_ID_SIZE:
            raise RoswireError(f"a goal id has {GOAL_ID_SIZE} bytes, got {len(goal_id)}")
        goal = _decode(ts, goal_cdr, f"{t}_Goal")
        request = ts.types[f"{t}_SendGoal_Request"](goal_id=_uuid(ts, goal_id), goal=goal)
        raw = self.send_goal_client.call_cdr(
            bytes(ts.serialize_cdr(request, f"{t}_SendGoal_Request")), timeout
        )
        response = _decode(ts, raw, f"{t}_SendGoal_Response")
        return GoalResponse(bool(response.accepted), _ns(response.stamp))

    def get_result(self, goal_id: bytes, timeout: float) -> ResultResponse:
        """Wait for the goal's result (the server answers when it has finished)."""
        ts, t = self._ts, self.typename
        request = ts.types[f"{t}_GetResult_Request"](goal_id=_uuid(ts, goal_id))
        raw = self.get_result_client.call_cdr(
            bytes(ts.serialize_cdr(request, f"{t}_GetResult_Request")), timeout
        )
        response = _decode(ts, raw, f"{t}_GetResult_Response")
        status: GoalStatus | int
        try:
            status = GoalStatus(int(response.status))
        except ValueError:
            status = int(response.status)
        return ResultResponse(status, bytes(ts.serialize_cdr(response.result, f"{t}_Result")))

    def cancel(self, goal_id: bytes, timeout: float) -> CancelResponse:
        """Ask the server to cancel ``goal_id``; raises ``ServiceError`` when it does not answer."""
        ts = self._ts
        info = ts.types["action_msgs/msg/GoalInfo"](goal_id=_uuid(ts, goal_id), stamp=_time(ts, 0))
        request = ts.types[f"{CANCEL_TYPE}_Request"](goal_info=info)
        raw = self.cancel_client.call_cdr(bytes(ts.serialize_cdr(request, f"{CANCEL_TYPE}_Request")), timeout)
        response = _decode(ts, raw, f"{CANCEL_TYPE}_Response")
        code: CancelCode | int
        try:
            code = CancelCode(int(response.return_code))
        except ValueError:
            code = int(response.return_code)
        canceling = tuple(
            bytes(np.asarray(g.goal_id.uuid, dtype=np.uint8).tobytes()) for g in response.goals_canceling
        )
        return CancelResponse(code, canceling)

    def _on_feedback(self, sample: RosSample) -> None:
        payload = sample.payload
        if len(payload) < 4 + GOAL_ID_SIZE:
            return
        goal_id = bytes(payload[4 : 4 + GOAL_ID_SIZE])
        with self._lock:
            listener = self._listeners.get(goal_id)
        if listener is None:
            return
        self.feedback_received += 1
        message = _decode(self._ts, payload, f"{self.typename}_FeedbackMessage")
        listener(bytes(self._ts.serialize_cdr(message.feedback, f"{self.typename}_Feedback")))
