"""Stream-processing applications that consume fleetlink's Kafka topics."""
