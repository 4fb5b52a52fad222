"""Commands, Kafka -> robots: mappings, the router that forwards them to the sites, statuses.

- ``mapping``: the ``commands:`` config (Kafka topic -> ROS topic template, type, repeat, lease);
- ``decode`` / ``plan``: a record -> command id, lease, robots, sites, envelopes (pure);
- ``directory`` / ``registrations``: robot -> site, from the registrations topic;
- ``forwarder``: the Zenoh query to a site, retried until a repeater settles it or the lease ends;
- ``offsets``: which offsets may be committed when records settle out of order;
- ``status_records`` / ``status_writer``: status events -> the command status topic;
- ``router``: the consumer tying it together, started by the uplink service.
"""
