"""The edge agent: one per robot network, beside its Zenoh router.

It discovers robots through rmw_zenoh liveliness, instantiates their mappings, runs each
mapping's stages, encodes Avro, keeps records in a durable spool and sends them over the WAN
until the uplink confirms Kafka has them.
"""
