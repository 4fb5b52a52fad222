package fleetlink.faultdetection;

/** Told of every state change, in the processing thread, before the command is produced. */
@FunctionalInterface
public interface CommandListener {
    void onCommand(LightCommand command, RobotState previous, Tally window);
}
