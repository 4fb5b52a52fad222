"""Fault detection for a TurtleBot 4 fleet, as a Quix Streams app on fleetlink's Kafka topics.

Public API: ``build_app(settings) -> quixstreams.Application`` and
``run(settings, stop_event)`` (in ``app``), ``FaultDetectionSettings`` (in ``settings``); the
pure rules are in ``rules``. See docs/fault_detection.md.
"""

from examples.fault_detection.settings import FaultDetectionSettings, Topics

__all__ = ["FaultDetectionSettings", "Topics"]
