"""A simulated TurtleBot 4 fleet (iRobot Create 3 interfaces) that speaks rmw_zenoh.

``model`` is the pure per-robot physics and sensor model (clock injected), ``messages`` turns
its readings into ROS messages, ``fleet`` runs robots on zenoh.
"""
