package fleetlink.faultdetection;

/** Where an event came from; one input topic each. */
public enum Sensor {
    IR_INTENSITY,
    HAZARD_DETECTION,
    KIDNAP_STATUS
}
