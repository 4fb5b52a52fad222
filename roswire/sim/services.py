"""The services and actions of one simulated TurtleBot 4 (Create 3), served over rmw_zenoh.

=============================  ==============================  ====================================
name (under ``/<robot>``)      type                            what it does to the model
=============================  ==============================  ====================================
``e_stop``                     irobot_create_msgs/srv/EStop    motors off (``e_stop_on``) or on
``reset_pose``                 irobot_create_msgs/srv/ResetPose  the pose estimate becomes the given one
``take_picture``               std_srvs/srv/Trigger            publishes a picture (sensor_msgs/Image,
                                                               250x250 rgb8) on the camera's topic
                                                               ``oakd/rgb/preview/image_raw``
``enable_motors``              std_srvs/srv/SetBool            motors enabled or not
``dock`` (action)              irobot_create_msgs/action/Dock  after ``dock_seconds`` the robot is on
                                                               its dock: standing still, put down
``undock`` (action)            irobot_create_msgs/action/Undock  leaves the dock (``undock_seconds``)
``drive_distance`` (action)    irobot_create_msgs/action/DriveDistance  drives straight; feedback: the
                                                               distance left; aborts when it cannot drive
=============================  ==============================  ====================================

Actions honour cancel requests (the goal ends CANCELED). Every change is reported to
``on_event(robot, text)``.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from fleetlink.roswire.action import GoalHandle, RosActionServer
from fleetlink.roswire.action_goals import GoalStatus
from fleetlink.roswire.service import RosServiceServer, ServiceCall
from fleetlink.roswire.sim.messages import CAMERA_TOPIC, IMAGE, MessageFactory
from fleetlink.roswire.sim.model import LINEAR_SPEED, RobotModel

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from fleetlink.roswire.node import RosNode
    from fleetlink.roswire.publisher import RosPublisher

log = logging.getLogger(__name__)

ESTOP = "irobot_create_msgs/srv/EStop"
RESET_POSE = "irobot_create_msgs/srv/ResetPose"
TRIGGER = "std_srvs/srv/Trigger"
SET_BOOL = "std_srvs/srv/SetBool"
DOCK = "irobot_create_msgs/action/Dock"
UNDOCK = "irobot_create_msgs/action/Undock"
DRIVE_DISTANCE = "irobot_create_msgs/action/DriveDistance"

SERVICES: dict[str, str] = {
    "e_stop": ESTOP,
    "reset_pose": RESET_POSE,
    "take_picture": TRIGGER,
    "enable_motors": SET_BOOL,
}
ACTIONS: dict[str, str] = {"dock": DOCK, "undock": UNDOCK, "drive_distance": DRIVE_DISTANCE}
FEEDBACK_PERIOD_S = 0.1

EventListener = Callable[[str, str], object]


@dataclass(frozen=True)
class Timing:
    """How long the dock and undock actions take, in seconds."""

    dock_seconds: float = 2.0
    undock_seconds: float = 1.0


DEFAULT_TIMING = Timing()


class RobotServices:
    """Serves one robot's services and actions on its node (``/<robot>/...``)."""

    def __init__(
        self,
        name: str,
        node: RosNode,
        model: RobotModel,
        lock: threading.Lock,
        ts: Typestore,
        *,
        timing: Timing = DEFAULT_TIMING,
        on_event: EventListener | None = None,
    ) -> None:
        self.name = name
        self.node = node
        self.model = model
        self.lock = lock
        self.ts = ts
        self.timing = timing
        self.on_event = on_event
        self.calls: dict[str, int] = {}
        self._servers: list[RosServiceServer | RosActionServer] = []
        self._camera: RosPublisher | None = None
        self._factory = MessageFactory(ts, name)

    def start(self) -> RobotServices:
        """Create the camera publisher and start the services and action servers; returns self."""
        handlers: dict[str, Callable[[Any], Any]] = {
            "e_stop": self._e_stop,
            "reset_pose": self._reset_pose,
            "take_picture": self._take_picture,
            "enable_motors": self._enable_motors,
        }
        self._camera = self.node.create_publisher(f"/{self.name}/{CAMERA_TOPIC}", IMAGE)
        for service, typename in SERVICES.items():
            self._servers.append(
                RosServiceServer(
                    self.node,
                    f"/{self.name}/{service}",
                    typename,
                    self._serve(service, typename, handlers[service]),
                ).start()
            )
        executes: dict[str, Callable[[GoalHandle], Any]] = {
            "dock": self._dock,
            "undock": self._undock,
            "drive_distance": self._drive_distance,
        }
        for action, typename in ACTIONS.items():
            self._servers.append(
                RosActionServer(self.node, f"/{self.name}/{action}", typename, executes[action]).start()
            )
        return self

    def stop(self) -> None:
        """Stop the services and action servers (the node stops the camera publisher)."""
        for server in self._servers:
            server.stop()
        self._servers = []

    def _event(self, text: str) -> None:
        log.info("robot %s: %s", self.name, text)
        if self.on_event is not None:
            self.on_event(self.name, text)

    def _serve(
        self, service: str, typename: str, handler: Callable[[Any], Any]
    ) -> Callable[[ServiceCall], bytes]:
        def serve(call: ServiceCall) -> bytes:
            request = self.ts.deserialize_cdr(call.payload, f"{typename}_Request")
            self.calls[service] = self.calls.get(service, 0) + 1
            response = handler(request)
            return bytes(self.ts.serialize_cdr(response, f"{typename}_Response"))

        return serve

    # -- services -----------------------------------------------------------------------------

    def _e_stop(self, request: Any) -> Any:
        with self.lock:
            self.model.e_stop = bool(request.e_stop_on)
        self._event(f"e-stop {'on' if request.e_stop_on else 'off'}")
        return self.ts.types[f"{ESTOP}_Response"](
            success=True, message="e-stop " + ("on" if request.e_stop_on else "off")
        )

    def _reset_pose(self, request: Any) -> Any:
        q = request.pose.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        with self.lock:
            self.model.reset_pose(float(request.pose.position.x), float(request.pose.position.y), yaw)
        self._event(f"pose reset to ({request.pose.position.x:.2f}, {request.pose.position.y:.2f})")
        return self.ts.types[f"{RESET_POSE}_Response"](structure_needs_at_least_one_member=0)

    def _take_picture(self, _request: Any) -> Any:
        with self.lock:
            self.model.pictures += 1
            number = self.model.pictures
        if self._camera is not None:
            self._camera.publish(self._factory.camera_image(time.time(), number))
        self._event(f"picture {number} taken")
        return self.ts.types[f"{TRIGGER}_Response"](success=True, message=f"picture {number} of {self.name}")

    def _enable_motors(self, request: Any) -> Any:
        with self.lock:
            self.model.motors_enabled = bool(request.data)
        state = "enabled" if request.data else "disabled"
        self._event(f"motors {state}")
        return self.ts.types[f"{SET_BOOL}_Response"](success=True, message=f"motors {state}")

    # -- actions ------------------------------------------------------------------------------

    def _dock(self, handle: GoalHandle) -> Any:
        result = self.ts.types[f"{DOCK}_Result"]
        feedback = self.ts.types[f"{DOCK}_Feedback"]
        with self.lock:
            if self.model.docked:
                return result(is_docked=True)
        self._event("docking")
        started = time.monotonic()
        while (left := self.timing.dock_seconds - (time.monotonic() - started)) > 0:
            handle.publish_feedback(feedback(sees_dock=left < self.timing.dock_seconds / 2))
            if handle.cancel_requested.wait(min(FEEDBACK_PERIOD_S, left)):
                self._event("docking canceled")
                return result(is_docked=False)
        with self.lock:
            self.model.dock()
        self._event("docked")
        return result(is_docked=True)

    def _undock(self, handle: GoalHandle) -> Any:
        result = self.ts.types[f"{UNDOCK}_Result"]
        with self.lock:
            if not self.model.docked:
                return result(is_docked=False)
        if handle.cancel_requested.wait(self.timing.undock_seconds):
            return result(is_docked=True)
        with self.lock:
            self.model.undock()
        self._event("undocked")
        return result(is_docked=False)

    def _drive_distance(self, handle: GoalHandle) -> Any:
        distance = abs(float(handle.goal.distance))
        with self.lock:
            self.model.drive_left = distance
        self._event(f"driving {distance:.2f} m")
        limit = time.monotonic() + 3 * distance / LINEAR_SPEED + 2.0
        feedback = self.ts.types[f"{DRIVE_DISTANCE}_Feedback"]
        while True:
            with self.lock:
                left, can_drive = self.model.drive_left, self.model.can_drive
            if left <= 0:
                break
            if not can_drive or time.monotonic() > limit:
                handle.finish(GoalStatus.ABORTED, self._pose_result())
                self._event("drive aborted: the robot cannot drive")
                return None
            handle.publish_feedback(feedback(remaining_travel_distance=left))
            if handle.cancel_requested.wait(FEEDBACK_PERIOD_S):
                with self.lock:
                    self.model.drive_left = 0.0
                self._event("drive canceled")
                return self._pose_result()
        self._event(f"drove {distance:.2f} m")
        return self._pose_result()

    def _pose_result(self) -> Any:
        t = self.ts.types
        with self.lock:
            x, y, yaw = self.model.x, self.model.y, self.model.yaw
        stamp = time.time()
        pose = t["geometry_msgs/msg/PoseStamped"](
            header=t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=int(stamp), nanosec=int((stamp % 1) * 1e9)),
                frame_id="odom",
            ),
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                orientation=t["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
                ),
            ),
        )
        return t[f"{DRIVE_DISTANCE}_Result"](pose=pose)
