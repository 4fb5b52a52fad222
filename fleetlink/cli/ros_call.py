"""``fleetlink ros call SERVICE TYPE 'YAML'`` (as ``ros2 service call``) and
``fleetlink ros action send_goal ACTION TYPE 'YAML'`` (as ``ros2 action send_goal``): an
rmw_zenoh service or action client on the zenoh network, printing the response, feedback and
result as YAML."""

from __future__ import annotations

import argparse
import sys
import uuid
from typing import Any, TextIO

import yaml

from fleetlink.common.errors import ConfigError
from fleetlink.common.zenoh_options import add_zenoh_arguments, options_from_args


def register_calls(ros_sub: Any, add_types: Any) -> None:
    """``ros call`` and ``ros action send_goal``; ``add_types`` adds --distro and --msg-path."""
    call = ros_sub.add_parser("call", help="call a ROS service once (like ros2 service call)")
    call.add_argument("service", help="the service, e.g. /tb4_01/e_stop")
    call.add_argument("type", help="the service type, e.g. irobot_create_msgs/srv/EStop")
    call.add_argument("values", nargs="?", default="{}", help="the request as YAML (default: {})")
    call.add_argument(
        "--timeout", type=float, default=10.0, metavar="S", help="wait at most S seconds (default 10)"
    )
    add_types(call)
    add_zenoh_arguments(call)
    call.set_defaults(handler=call_command)

    action = ros_sub.add_parser("action", help="send an action goal (like ros2 action send_goal)")
    action_sub = action.add_subparsers(dest="action_command", metavar="COMMAND", required=True)
    send = action_sub.add_parser("send_goal", help="send one goal, print feedback and the result")
    send.add_argument("action", help="the action, e.g. /tb4_01/dock")
    send.add_argument("type", help="the action type, e.g. irobot_create_msgs/action/Dock")
    send.add_argument("values", nargs="?", default="{}", help="the goal as YAML (default: {})")
    send.add_argument("--feedback", "-f", action="store_true", help="print the goal's feedback")
    send.add_argument(
        "--timeout", type=float, default=60.0, metavar="S", help="wait at most S seconds (default 60)"
    )
    add_types(send)
    add_zenoh_arguments(send)
    send.set_defaults(handler=send_goal_command)


def _values(text: str) -> Any:
    try:
        return yaml.safe_load(text) or {}
    except yaml.YAMLError as exc:
        raise ConfigError(f"the values are not YAML: {exc}") from None


def _node(args: argparse.Namespace) -> Any:
    from fleetlink.cli.ros_common import typestore
    from fleetlink.roswire.node import RosNode
    from fleetlink.roswire.session import ros_session_config

    ts = typestore(args)
    config = ros_session_config(options_from_args(args))
    return RosNode(
        "fleetlink_cli", "/", domain_id=args.domain_id, config=config, typestore=ts, distro=args.distro
    )


def _dump(data: Any) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=False).rstrip()


def call_command(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Call a ROS service once, printing request and response; returns 1 when no server or response came."""
    from fleetlink.roswire.service import RosServiceClient, ServiceError
    from fleetlink.schemas.messages import from_data, to_data

    with _node(args) as node:
        ts = node.typestore
        request = from_data(ts, f"{args.type}_Request", _values(args.values))
        client = RosServiceClient(node, args.service, args.type).start()
        print(f"waiting for service {client.service} ...", file=out)
        if not client.wait_for_server(args.timeout):
            print(f"no server for {client.service} within {args.timeout:g} s", file=sys.stderr)
            return 1
        print(f"requester: making request: {_dump(to_data(request))}", file=out)
        try:
            raw = client.call_cdr(bytes(ts.serialize_cdr(request, f"{args.type}_Request")), args.timeout)
        except ServiceError as exc:
            print(f"no response: {exc.reason}", file=sys.stderr)
            return 1
        response = ts.deserialize_cdr(raw, f"{args.type}_Response")
        print(f"response:\n{_dump(to_data(response))}", file=out)
    return 0


def send_goal_command(args: argparse.Namespace, out: TextIO = sys.stdout) -> int:
    """Send one action goal, print its feedback (with ``--feedback``) and result.

    Returns 0 when the goal succeeded, 1 when it was rejected, failed or not answered in time.
    """
    from fleetlink.roswire.action import RosActionClient
    from fleetlink.roswire.action_goals import GoalStatus
    from fleetlink.roswire.service import ServiceError
    from fleetlink.schemas.messages import from_data, to_data

    with _node(args) as node:
        ts = node.typestore
        goal = from_data(ts, f"{args.type}_Goal", _values(args.values))
        client = RosActionClient(node, args.action, args.type).start()
        if not client.wait_for_server(args.timeout):
            print(f"no action server {client.action} within {args.timeout:g} s", file=sys.stderr)
            return 1
        goal_id = uuid.uuid4()
        if args.feedback:

            def feedback(cdr: bytes) -> None:
                message = ts.deserialize_cdr(cdr, f"{args.type}_Feedback")
                print(f"feedback:\n{_dump(to_data(message))}", file=out, flush=True)

            client.listen(goal_id.bytes, feedback)
        print(f"sending goal:\n{_dump(to_data(goal))}", file=out)
        try:
            answer = client.send_goal(
                goal_id.bytes, bytes(ts.serialize_cdr(goal, f"{args.type}_Goal")), args.timeout
            )
            if not answer.accepted:
                print("goal rejected", file=sys.stderr)
                return 1
            print(f"goal accepted with ID: {goal_id.hex}", file=out)
            result = client.get_result(goal_id.bytes, args.timeout)
        except ServiceError as exc:
            print(f"no answer: {exc.reason}", file=sys.stderr)
            return 1
        message = ts.deserialize_cdr(result.result_cdr, f"{args.type}_Result")
        status = result.status.name if isinstance(result.status, GoalStatus) else str(result.status)
        print(f"result:\n{_dump(to_data(message))}\ngoal finished with status: {status}", file=out)
        return 0 if result.status == GoalStatus.SUCCEEDED else 1
