package fleetlink.faultdetection;

import java.util.Optional;

/** A robot's memory after one window, and the command it yields (only on a change of state). */
public record Transition(RobotMemory memory, Optional<LightCommand> command) {}
