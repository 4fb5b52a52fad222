package fleetlink.faultdetection;

import java.util.ArrayList;
import java.util.List;
import ros.builtin_interfaces.msg.Time;
import ros.irobot_create_msgs.msg.LedColor;
import ros.irobot_create_msgs.msg.LightringLeds;
import ros.std_msgs.msg.Header;

/**
 * One light-ring command: the robot, the state it entered, and when (window end, ms).
 *
 * @param robot the robot (the Kafka key of its records)
 * @param state the state it entered: red for failed, green for running
 * @param stampMs the end of the deciding window, the command's timestamp
 */
public record LightCommand(String robot, RobotState state, long stampMs) {
    /** irobot_create_msgs/msg/LightringLeds: LedColor[6] leds. */
    public static final int LED_COUNT = 6;

    /** Deterministic: re-processing the same decision yields the same id (receivers can dedupe). */
    public String commandId() {
        return robot + "-" + state.label() + "-" + stampMs;
    }

    /** The LightringLeds record: all six LEDs red (failed) or green (running), stamped at the window end. */
    public LightringLeds toLightringLeds() {
        int red = state == RobotState.FAILED ? 255 : 0;
        int green = state == RobotState.RUNNING ? 255 : 0;
        List<LedColor> leds = new ArrayList<>(LED_COUNT);
        for (int i = 0; i < LED_COUNT; i++) {
            leds.add(LedColor.newBuilder().setRed(red).setGreen(green).setBlue(0).build());
        }
        Time stamp = Time.newBuilder()
                .setSec(Math.toIntExact(Math.floorDiv(stampMs, 1000L)))
                .setNanosec(Math.floorMod(stampMs, 1000L) * 1_000_000L)
                .build();
        return LightringLeds.newBuilder()
                .setHeader(Header.newBuilder().setStamp(stamp).setFrameId("").build())
                .setLeds(leds)
                .setOverrideSystem(true)
                .build();
    }
}
