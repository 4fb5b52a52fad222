"""roswire: a ROS-free rmw_zenoh peer.

Discover ROS 2 graphs from liveliness tokens, receive and publish topics exactly as rmw_zenoh
does (keys, tokens, attachments, CDR), and simulate or replay robots. Pure protocol modules
(``names``, ``qos``, ``tokens``, ``attachment``, ``gid``, ``graph``, ``robots``) have no I/O; the
Zenoh adapters (``node``, ``discovery``, ``subscriber``, ``publisher``) connect in ``start()``.
"""
