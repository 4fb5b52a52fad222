"""ROS 2 service calls and action goals from Kafka (docs/services.md): mappings, planning,
conversion, and the outcomes the sites send back, produced to Kafka."""
