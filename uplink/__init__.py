"""The uplink: the cloud side of fleetlink, between the edges (over Zenoh) and Kafka.

It receives acknowledged batches from edge agents, registers schemas, produces records with
``acks=all`` and idempotence, answers each batch only after Kafka acknowledged every record,
and carries commands from Kafka back to the sites. It keeps no durable state of its own.
"""
