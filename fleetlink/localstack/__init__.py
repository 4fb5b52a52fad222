"""A local Kafka broker and schema registry for tests and the demo, as plain processes.

Apache Kafka (KRaft, broker+controller in one JVM) and Apicurio Registry come from Maven
Central, fetched once with Maven into a cache folder and reused; both run on loopback ports
and are stopped by PID. Nothing here is a stand-in: they are the real servers.
"""
