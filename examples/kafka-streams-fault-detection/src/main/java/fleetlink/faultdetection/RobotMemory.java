package fleetlink.faultdetection;

/**
 * What the state store keeps per robot: its state and the end of the newest window judged.
 *
 * @param state running or failed
 * @param lastWindowEndMs end (ms) of the newest window judged; -1 before the first
 */
public record RobotMemory(RobotState state, long lastWindowEndMs) {
    /** Every robot starts running, before any window has been judged: no command at start-up. */
    public static final RobotMemory INITIAL = new RobotMemory(RobotState.RUNNING, -1);
}
