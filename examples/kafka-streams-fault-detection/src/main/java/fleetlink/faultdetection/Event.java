package fleetlink.faultdetection;

/** One sensor record, judged: does it say the robot failed? Stamped with the record timestamp. */
public record Event(Sensor sensor, boolean failure, long timestampMs) {}
