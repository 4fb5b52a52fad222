"""``fleetlink demo``: the warehouse loop, end to end, on one machine.

Simulated TurtleBot 4 robots publish over rmw_zenoh; the edge agent maps their IR, hazard and
kidnap topics many-to-one into Kafka through the uplink; a Quix Streams app detects a robot
that was picked up and writes one light-ring command; the uplink routes it back to the site,
where the repeater publishes it to the robot, whose light ring turns red (and green again
after it is put down).
"""
