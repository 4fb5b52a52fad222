"""Fault detection for a TurtleBot 4 fleet, as a Quix Streams app on fleetlink's Kafka topics.

Public API: ``build_app(settings) -> quixstreams.Application``, ``run(settings, stop_event)``
and ``FaultDetectionSettings``; the pure rules are in ``rules``. See docs/fault_detection.md.
"""

from fleetlink.examples.fault_detection.app import build_app, run
from fleetlink.examples.fault_detection.rules import LightCommand, RobotState
from fleetlink.examples.fault_detection.settings import FaultDetectionSettings, Topics

__all__ = ["FaultDetectionSettings", "LightCommand", "RobotState", "Topics", "build_app", "run"]
