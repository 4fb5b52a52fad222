"""Repeaters: commands from Kafka replayed near the robots as rmw_zenoh publications.

A repeater publishes each command as a proper ROS 2 publisher would, repeats it locally every
period while its lease holds, hands it at once to subscribers that appear late, applies each
command id once, and stops when its link to the uplink has been gone longer than the lease.
"""
