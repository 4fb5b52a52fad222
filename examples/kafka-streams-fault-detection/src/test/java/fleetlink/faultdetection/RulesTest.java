package fleetlink.faultdetection;

import static org.junit.jupiter.api.Assertions.assertEquals;
import static org.junit.jupiter.api.Assertions.assertFalse;
import static org.junit.jupiter.api.Assertions.assertThrows;
import static org.junit.jupiter.api.Assertions.assertTrue;

import java.util.List;
import java.util.Optional;
import java.util.Set;
import org.junit.jupiter.api.Test;
import org.junit.jupiter.params.ParameterizedTest;
import org.junit.jupiter.params.provider.CsvSource;
import ros.builtin_interfaces.msg.Time;
import ros.irobot_create_msgs.msg.HazardDetection;
import ros.irobot_create_msgs.msg.HazardDetectionVector;
import ros.irobot_create_msgs.msg.IrIntensity;
import ros.irobot_create_msgs.msg.IrIntensityVector;
import ros.irobot_create_msgs.msg.KidnapStatus;
import ros.irobot_create_msgs.msg.LedColor;
import ros.irobot_create_msgs.msg.LightringLeds;
import ros.std_msgs.msg.Header;

/** The same tables as tests/unit/examples/fault_detection/test_rules.py, for the Java rules. */
class RulesTest {
    static final Header HEADER = Header.newBuilder()
            .setStamp(Time.newBuilder().setSec(1).setNanosec(0).build()).setFrameId("base_link").build();

    static IrIntensityVector ir(int... values) {
        List<IrIntensity> readings = java.util.Arrays.stream(values)
                .mapToObj(v -> IrIntensity.newBuilder().setHeader(HEADER).setValue(v).build()).toList();
        return IrIntensityVector.newBuilder().setHeader(HEADER).setReadings(readings).build();
    }

    static HazardDetectionVector hazards(int... types) {
        List<HazardDetection> detections = java.util.Arrays.stream(types)
                .mapToObj(t -> HazardDetection.newBuilder().setHeader(HEADER).setType(t).build()).toList();
        return HazardDetectionVector.newBuilder().setHeader(HEADER).setDetections(detections).build();
    }

    @Test
    void irFailsOnlyWhenEveryReadingIsAboveTheThreshold() {
        assertTrue(Rules.irFailure(ir(3900, 3500, 4000, 3300, 3600, 3100, 3700), 3000));
        assertFalse(Rules.irFailure(ir(3900, 3500, 4000, 3300, 3600, 3100, 12), 3000));
        assertFalse(Rules.irFailure(ir(3000, 3001), 3000)); // strictly above
        assertTrue(Rules.irFailure(ir(3001), 3000));
        assertFalse(Rules.irFailure(ir(), 3000)); // no readings, no evidence
    }

    @Test
    void hazardsFailOnAnyFailureType() {
        Set<Integer> failing = RuleConfig.defaults().failureHazards();
        assertTrue(Rules.hazardFailure(hazards(1, RuleConfig.HAZARD_WHEEL_DROP), failing));
        assertTrue(Rules.hazardFailure(hazards(RuleConfig.HAZARD_CLIFF), failing));
        assertFalse(Rules.hazardFailure(hazards(1, 3), failing));
        assertFalse(Rules.hazardFailure(hazards(), failing));
        assertTrue(Rules.hazardFailure(hazards(1), Set.of(1)));
    }

    @Test
    void kidnapFailsWhenKidnapped() {
        assertTrue(Rules.kidnapFailure(KidnapStatus.newBuilder().setHeader(HEADER).setIsKidnapped(true).build()));
        assertFalse(Rules.kidnapFailure(KidnapStatus.newBuilder().setHeader(HEADER).setIsKidnapped(false).build()));
    }

    @ParameterizedTest
    @CsvSource({
        // events, failures, minEvents, verdict
        "5, 5, 2, FAILED",
        "5, 0, 2, RUNNING",
        "5, 3, 2, ",
        "1, 1, 2, ",
        "1, 0, 2, ",
        "1, 1, 1, FAILED",
        "0, 0, 1, ",
        "2, 2, 2, FAILED",
    })
    void windowVerdicts(long events, long failures, int minEvents, RobotState expected) {
        assertEquals(Optional.ofNullable(expected), Rules.windowVerdict(events, failures, minEvents));
    }

    @Test
    void aWindowCannotHoldMoreFailuresThanEvents() {
        assertThrows(IllegalArgumentException.class, () -> Rules.windowVerdict(2, 3, 1));
        assertThrows(IllegalArgumentException.class, () -> Rules.windowVerdict(2, -1, 1));
    }

    @Test
    void onlyAWindowReachedByAnEventIsComplete() {
        assertTrue(Rules.windowComplete(1000, 1000));
        assertTrue(Rules.windowComplete(1000, 1500));
        assertFalse(Rules.windowComplete(1000, 999));
        assertFalse(Rules.windowComplete(1000, Tally.EMPTY.newestMs()));
    }

    @Test
    void aChangeOfStateYieldsOneCommandAndNothingElseDoes() {
        RobotMemory start = RobotMemory.INITIAL;
        Transition none = Rules.step("tb4_01", start, Optional.of(RobotState.RUNNING), 1000);
        assertEquals(new RobotMemory(RobotState.RUNNING, 1000), none.memory());
        assertTrue(none.command().isEmpty());

        Transition red = Rules.step("tb4_01", none.memory(), Optional.of(RobotState.FAILED), 2000);
        assertEquals(new RobotMemory(RobotState.FAILED, 2000), red.memory());
        assertEquals(Optional.of(new LightCommand("tb4_01", RobotState.FAILED, 2000)), red.command());

        Transition again = Rules.step("tb4_01", red.memory(), Optional.of(RobotState.FAILED), 2100);
        assertTrue(again.command().isEmpty());
        Transition mixed = Rules.step("tb4_01", again.memory(), Optional.empty(), 2200);
        assertEquals(new RobotMemory(RobotState.FAILED, 2200), mixed.memory());
        assertTrue(mixed.command().isEmpty());

        Transition stale = Rules.step("tb4_01", mixed.memory(), Optional.of(RobotState.RUNNING), 2150);
        assertEquals(mixed.memory(), stale.memory()); // an older window never moves the state back
        assertTrue(stale.command().isEmpty());

        Transition green = Rules.step("tb4_01", mixed.memory(), Optional.of(RobotState.RUNNING), 2200);
        assertEquals(Optional.of(new LightCommand("tb4_01", RobotState.RUNNING, 2200)), green.command());
    }

    @Test
    void commandsCarryADeterministicIdAndSixLeds() {
        LightCommand red = new LightCommand("tb4_02", RobotState.FAILED, 1_700_000_004_123L);
        assertEquals("tb4_02-failed-1700000004123", red.commandId());
        LightringLeds record = red.toLightringLeds();
        assertEquals(1_700_000_004, record.getHeader().getStamp().getSec());
        assertEquals(123_000_000L, record.getHeader().getStamp().getNanosec());
        assertEquals("", record.getHeader().getFrameId().toString());
        assertTrue(record.getOverrideSystem());
        assertEquals(LightCommand.LED_COUNT, record.getLeds().size());
        for (LedColor led : record.getLeds()) {
            assertEquals(List.of(255, 0, 0), List.of(led.getRed(), led.getGreen(), led.getBlue()));
        }
        LedColor green = new LightCommand("tb4_02", RobotState.RUNNING, 0).toLightringLeds().getLeds().get(5);
        assertEquals(List.of(0, 255, 0), List.of(green.getRed(), green.getGreen(), green.getBlue()));
    }
}
