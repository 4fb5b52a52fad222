"""The edge agent's runtime: the adapters between Zenoh, the mapping engine, the spool and the WAN.

- ``records``: ROS samples -> Kafka records (pure: mappings, stages, Avro, dead letters);
  ``fastpath``: the same for mappings that take CDR straight to Avro, one template per topic;
  ``outgoing``: what they produce (spool payloads per delivery class) and the mapping counters.
- ``encoding`` / ``schema_book``: Avro encoders for derived schemas; fingerprint -> schema JSON.
- ``intake``: the bounded hand-off from Zenoh callbacks to the processing thread.
- ``processor``: the thread that turns samples into records and appends them to the buffers.
- ``subscriptions``: discovered publishers -> one ``RosSubscriber`` per mapped topic (each with
  a ring channel drained by its own thread).
- ``registration``: robot registration events (Kafka record + ROS topic).
- ``backoff`` / ``sender`` / ``transport``: the acknowledged WAN hop to the uplink.
"""
