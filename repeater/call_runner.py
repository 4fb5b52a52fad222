"""Make service calls and run action goals near the robots, as an rmw_zenoh client.

Each accepted call envelope runs on a worker thread (``workers`` at once) and ends in exactly
one final :class:`~fleetlink.wire.calls.Outcome`:

* **service**: wait (until the deadline) for the robot's service server (its ``SS`` token) —
  none: ``unavailable``, the request was never sent; call it — the response: ``ok``; none by
  the deadline: ``timeout``; the server went away during the call: ``error`` (it may or may
  not have handled the request; it is not sent again);
* **goal**: wait for the action server as above; ``send_goal`` — ``rejected``, or ``accepted``
  (not final); then the goal's feedback is passed on as it comes and ``get_result`` waits for
  the result: ``succeeded`` / ``canceled`` / ``aborted`` with the result; still running at the
  deadline: the goal is canceled on the robot and reported ``timeout``; the server went away:
  ``error``;
* **cancel**: the robot's ``cancel_goal`` answer: ``cancel-accepted``, ``cancel-rejected``,
  ``cancel-unknown-goal`` or ``cancel-terminated`` (the goal had finished).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

from fleetlink.roswire.action import RosActionClient
from fleetlink.roswire.action_goals import CancelCode, GoalStatus, goal_id_bytes, status_label
from fleetlink.roswire.errors import RoswireError
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.service import (
    RosServiceClient,
    ServiceError,
    ServiceGoneError,
    ServiceTimeoutError,
)
from fleetlink.wire.calls import CallEnvelope, Outcome

log = logging.getLogger(__name__)

SEND_GOAL_TIMEOUT_S = 10.0
CANCEL_TIMEOUT_S = 5.0
MAX_CLIENTS = 1_000

Emit = Callable[[Outcome, bool], None]
"""Gets every outcome and whether it is the call's final one."""

_CANCEL_STATE = {
    CancelCode.ERROR_NONE: "cancel-accepted",
    CancelCode.ERROR_REJECTED: "cancel-rejected",
    CancelCode.ERROR_UNKNOWN_GOAL_ID: "cancel-unknown-goal",
    CancelCode.ERROR_GOAL_TERMINATED: "cancel-terminated",
}


@dataclass
class RunnerStats:
    """Counters of a ``CallRunner``: calls started, feedback passed on, outcomes emitted per status."""

    calls: int = 0
    feedback: int = 0
    outcomes: dict[str, int] = field(default_factory=dict)


class CallRunner:
    """Runs accepted calls, goals and cancels as an rmw_zenoh client on a pool of worker threads.

    Each call ends in exactly one final outcome given to ``emit``; clients are kept per (name, type),
    at most ``MAX_CLIENTS`` (the least recently used one is stopped).
    """

    def __init__(
        self, node: RosNode, emit: Emit, *, clock: Callable[[], float] = time.time, workers: int = 32
    ) -> None:
        self._node = node
        self._emit = emit
        self._clock = clock
        self._stop = threading.Event()
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="repeater-call")
        self._lock = threading.Lock()
        self._clients: OrderedDict[tuple[str, str], RosServiceClient | RosActionClient] = OrderedDict()
        self.stats = RunnerStats()

    def submit(self, env: CallEnvelope, *, resume: bool = False) -> None:
        """Run ``env`` (``resume``: a goal accepted before a restart: only wait for its result)."""
        self._pool.submit(self._run, env, resume)

    def stop(self) -> None:
        """Stop waiting for servers, drop queued calls, wait for the running ones and stop every client."""
        self._stop.set()
        self._pool.shutdown(wait=True, cancel_futures=True)
        with self._lock:
            clients = list(self._clients.values())
            self._clients.clear()
        for client in clients:
            client.stop()

    # -- one call --------------------------------------------------------------------------------

    def _run(self, env: CallEnvelope, resume: bool) -> None:
        self.stats.calls += 1
        try:
            if env.kind == "service":
                self._service(env)
            elif env.kind == "goal":
                self._goal(env, resume)
            else:
                self._cancel(env)
        except Exception as exc:  # a bug must still end the call with an outcome
            log.exception("call %s (%s) failed", env.call_id, env.kind)
            kind = {"service": "reply", "goal": "result", "cancel": "cancel"}[env.kind]
            status = "cancel-error" if env.kind == "cancel" else "error"
            self._out(env, kind, status, f"repeater failure: {exc!r}", final=True)

    def _left(self, env: CallEnvelope) -> float:
        return env.deadline_ms / 1000 - self._clock()

    def _out(
        self,
        env: CallEnvelope,
        kind: str,
        status: str,
        detail: str = "",
        payload: bytes | None = None,
        *,
        final: bool,
    ) -> None:
        at_ms = int(self._clock() * 1000)
        if status == "timeout":  # a timer may fire a fraction of a ms early: the deadline is what passed
            at_ms = max(at_ms, env.deadline_ms)
        out = Outcome(
            kind,  # type: ignore[arg-type]
            env.call_id,
            env.robot,
            env.mapping,
            status,
            at_ms,
            detail,
            payload,
            env.issued_at_ms,
        )
        self.stats.outcomes[status] = self.stats.outcomes.get(status, 0) + 1
        self._emit(out, final)

    def _client(self, env: CallEnvelope) -> RosServiceClient | RosActionClient:
        key = (env.ros_name, env.ros_type)
        with self._lock:
            client = self._clients.get(key)
            if client is not None:
                self._clients.move_to_end(key)
                return client
            if env.kind == "service":
                client = RosServiceClient(self._node, env.ros_name, env.ros_type).start()
            else:
                client = RosActionClient(self._node, env.ros_name, env.ros_type).start()
            self._clients[key] = client
            evicted = self._clients.popitem(last=False)[1] if len(self._clients) > MAX_CLIENTS else None
        if evicted is not None:
            evicted.stop()
        return client

    def _service(self, env: CallEnvelope) -> None:
        client = self._client(env)
        if not isinstance(client, RosServiceClient):
            raise RoswireError(f"{env.ros_name} is used as a service and as an action")
        if not client.wait_for_server(max(self._left(env), 0.0), stop=self._stop):
            self._out(
                env, "reply", "unavailable", f"no server for {env.ros_name} before the deadline", final=True
            )
            return
        timeout = self._left(env)
        if timeout <= 0:
            self._out(env, "reply", "timeout", "the deadline passed before the call", final=True)
            return
        try:
            response = client.call_cdr(env.payload, timeout)
        except ServiceTimeoutError as exc:
            self._out(env, "reply", "timeout", exc.reason, final=True)
        except ServiceGoneError as exc:
            detail = f"{exc.reason}; the server went away during the call: it may or may not have handled it"
            self._out(env, "reply", "error", detail, final=True)
        except ServiceError as exc:
            self._out(env, "reply", "error", exc.reason, final=True)
        else:
            self._out(env, "reply", "ok", "", response, final=True)

    def _action(self, env: CallEnvelope) -> RosActionClient:
        client = self._client(env)
        if not isinstance(client, RosActionClient):
            raise RoswireError(f"{env.ros_name} is used as a service and as an action")
        return client

    def _goal(self, env: CallEnvelope, resume: bool) -> None:
        client = self._action(env)
        goal_id = goal_id_bytes(env.call_id)

        def feedback(cdr: bytes) -> None:
            self.stats.feedback += 1
            self._out(env, "feedback", "feedback", "", cdr, final=False)

        client.listen(goal_id, feedback)
        try:
            if not resume and not self._send_goal(env, client, goal_id):
                return
            self._wait_result(env, client, goal_id)
        finally:
            client.listen(goal_id, None)

    def _send_goal(self, env: CallEnvelope, client: RosActionClient, goal_id: bytes) -> bool:
        if not client.wait_for_server(max(self._left(env), 0.0), stop=self._stop):
            self._out(
                env,
                "result",
                "unavailable",
                f"no action server {env.ros_name} before the deadline",
                final=True,
            )
            return False
        try:
            response = client.send_goal(
                goal_id, env.payload, min(max(self._left(env), 0.05), SEND_GOAL_TIMEOUT_S)
            )
        except ServiceTimeoutError as exc:
            self._out(env, "result", "timeout", f"send_goal: {exc.reason}", final=True)
            return False
        except (ServiceError, RoswireError) as exc:
            self._out(env, "result", "error", f"send_goal: {exc}", final=True)
            return False
        if not response.accepted:
            self._out(env, "result", "rejected", "the action server rejected the goal", final=True)
            return False
        self._out(env, "result", "accepted", "", final=False)
        return True

    def _wait_result(self, env: CallEnvelope, client: RosActionClient, goal_id: bytes) -> None:
        try:
            result = client.get_result(goal_id, max(self._left(env), 0.05))
        except ServiceTimeoutError:
            self._out(env, "result", "timeout", self._cancel_at_deadline(client, goal_id), final=True)
            return
        except ServiceGoneError as exc:
            detail = f"the action server went away during the goal ({exc.reason})"
            self._out(env, "result", "error", detail, final=True)
            return
        except ServiceError as exc:
            self._out(env, "result", "error", f"get_result: {exc.reason}", final=True)
            return
        status = result.status
        if isinstance(status, GoalStatus) and status.terminal:
            self._out(env, "result", status.label, "", result.result_cdr, final=True)
            return
        detail = f"the action server answered get_result with {status_label(int(status))}"
        self._out(env, "result", "error", detail, final=True)

    def _cancel_at_deadline(self, client: RosActionClient, goal_id: bytes) -> str:
        try:
            answer = client.cancel(goal_id, CANCEL_TIMEOUT_S)
        except ServiceError as exc:
            return f"still running at the deadline; canceling it failed: {exc.reason}"
        code = answer.code
        meaning = code.meaning if isinstance(code, CancelCode) else f"return code {code}"
        return f"still running at the deadline; canceled on the robot: {meaning}"

    def _cancel(self, env: CallEnvelope) -> None:
        client = self._action(env)
        goal_id = goal_id_bytes(env.call_id)
        if not client.wait_for_server(max(self._left(env), 0.0), stop=self._stop):
            self._out(env, "cancel", "cancel-unavailable", f"no action server {env.ros_name}", final=True)
            return
        try:
            answer = client.cancel(goal_id, max(self._left(env), 0.05))
        except ServiceTimeoutError as exc:
            self._out(env, "cancel", "cancel-timeout", exc.reason, final=True)
            return
        except ServiceError as exc:
            self._out(env, "cancel", "cancel-error", exc.reason, final=True)
            return
        code = answer.code
        if isinstance(code, CancelCode):
            self._out(env, "cancel", _CANCEL_STATE[code], code.meaning, final=True)
        else:
            self._out(env, "cancel", "cancel-error", f"unknown return code {code}", final=True)
