package fleetlink.faultdetection;

/** What the app believes about a robot: running, or failed (picked up, wheels in the air). */
public enum RobotState {
    RUNNING("running"),
    FAILED("failed");

    private final String label;

    RobotState(String label) {
        this.label = label;
    }

    /** The lower-case name used in logs and command ids, as the Python app writes it. */
    public String label() {
        return label;
    }

    @Override
    public String toString() {
        return label;
    }
}
