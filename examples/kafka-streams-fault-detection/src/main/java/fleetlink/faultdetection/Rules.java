package fleetlink.faultdetection;

import java.util.List;
import java.util.Optional;
import java.util.Set;
import ros.irobot_create_msgs.msg.HazardDetection;
import ros.irobot_create_msgs.msg.HazardDetectionVector;
import ros.irobot_create_msgs.msg.IrIntensity;
import ros.irobot_create_msgs.msg.IrIntensityVector;
import ros.irobot_create_msgs.msg.KidnapStatus;

/**
 * The fault-detection rules, as pure functions: no Kafka, no clock, no disk. The same rules as
 * the Python app's {@code examples/fault_detection/rules.py}, step for step.
 *
 * <ol>
 *   <li><b>Event → failure</b>: kidnap status says {@code is_kidnapped}; a hazard detection holds
 *       a failure hazard (WHEEL_DROP, CLIFF); an IR vector has at least one reading and every
 *       reading is strictly above the threshold.
 *   <li><b>Window → verdict</b>: every event failed → FAILED; none failed → RUNNING; mixed, or
 *       fewer than {@code minEvents} → none (keep the current state). Only a window whose end an
 *       event has reached is judged.
 *   <li><b>Verdict → transition</b>: a change of state yields exactly one command; a window that
 *       ends before the newest one judged is ignored, so the state only moves forward in event time.
 * </ol>
 */
public final class Rules {
    private Rules() {}

    // --- 1. event -> failure -------------------------------------------------------------

    /** IrIntensityVector: every reading strictly above {@code threshold} (and at least one). */
    public static boolean irFailure(IrIntensityVector record, int threshold) {
        List<IrIntensity> readings = record.getReadings();
        return !readings.isEmpty() && readings.stream().allMatch(r -> r.getValue() > threshold);
    }

    /** HazardDetectionVector: any detection whose type is one of {@code failureHazards}. */
    public static boolean hazardFailure(HazardDetectionVector record, Set<Integer> failureHazards) {
        return record.getDetections().stream().map(HazardDetection::getType).anyMatch(failureHazards::contains);
    }

    /** KidnapStatus: {@code is_kidnapped}. */
    public static boolean kidnapFailure(KidnapStatus record) {
        return record.getIsKidnapped();
    }

    // --- 2. window -> verdict ------------------------------------------------------------

    /**
     * Whether a sliding window covers its whole duration of events. Kafka Streams also emits the
     * windows that start just after an event and end in the future; those hold only the newest
     * events. Only a window whose end an event has reached is judged.
     */
    public static boolean windowComplete(long endMs, long newestEventMs) {
        return newestEventMs >= endMs;
    }

    /** All events failed → FAILED; none failed → RUNNING; mixed or too few events → empty. */
    public static Optional<RobotState> windowVerdict(long events, long failures, int minEvents) {
        if (failures < 0 || failures > events) {
            throw new IllegalArgumentException("window with " + events + " events cannot hold " + failures + " failures");
        }
        if (events < Math.max(minEvents, 1)) {
            return Optional.empty();
        }
        if (failures == events) {
            return Optional.of(RobotState.FAILED);
        }
        if (failures == 0) {
            return Optional.of(RobotState.RUNNING);
        }
        return Optional.empty();
    }

    // --- 3. verdict -> transition -> command ---------------------------------------------

    /** Apply one window's verdict to a robot's memory; a command only on a change of state. */
    public static Transition step(String robot, RobotMemory memory, Optional<RobotState> verdict, long windowEndMs) {
        if (windowEndMs < memory.lastWindowEndMs()) {
            return new Transition(memory, Optional.empty());
        }
        if (verdict.isEmpty() || verdict.get() == memory.state()) {
            return new Transition(new RobotMemory(memory.state(), windowEndMs), Optional.empty());
        }
        RobotState next = verdict.get();
        return new Transition(new RobotMemory(next, windowEndMs), Optional.of(new LightCommand(robot, next, windowEndMs)));
    }
}
