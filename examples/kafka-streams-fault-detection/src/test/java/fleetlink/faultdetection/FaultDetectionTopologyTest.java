package fleetlink.faultdetection;

import static java.nio.charset.StandardCharsets.UTF_8;
import static org.junit.jupiter.api.Assertions.assertEquals;

import java.nio.file.Path;
import java.time.Instant;
import java.util.ArrayList;
import java.util.Comparator;
import java.util.List;
import java.util.Properties;
import java.util.function.BiPredicate;
import org.apache.kafka.common.serialization.Serdes;
import org.apache.kafka.streams.StreamsConfig;
import org.apache.kafka.streams.TestInputTopic;
import org.apache.kafka.streams.TestOutputTopic;
import org.apache.kafka.streams.TopologyTestDriver;
import org.apache.kafka.streams.state.BuiltInDslStoreSuppliers;
import org.apache.kafka.streams.state.Stores;
import org.apache.kafka.streams.test.TestRecord;
import org.junit.jupiter.api.Test;
import org.junit.jupiter.api.io.TempDir;
import ros.irobot_create_msgs.msg.HazardDetectionVector;
import ros.irobot_create_msgs.msg.IrIntensityVector;
import ros.irobot_create_msgs.msg.KidnapStatus;
import ros.irobot_create_msgs.msg.LightringLeds;

/**
 * The whole topology in event time, without a broker: the scenario of
 * tests/integration/test_fault_detection_app.py. Each robot reports every sensor every 100 ms
 * (IR at +0, kidnap at +30, hazards at +60 ms); tb4_01 stays healthy, tb4_02 is picked up from
 * 2.0 s to 5.5 s, tb4_03 has one kidnapped reading at 4.03 s. Window 2 s: the last healthy
 * record of tb4_02 is at 1.96 s, so red at 4.0 s; its last failing one at 5.46 s, so green at 7.5 s.
 */
class FaultDetectionTopologyTest {
    static final long T0 = 1_700_000_000_000L;
    static final int[] HEALTHY_IR = {12, 40, 7, 300, 25, 0, 18};
    static final int[] PICKED_UP_IR = {3900, 3500, 4000, 3300, 3600, 3100, 3700};

    record Reading(String robot, String sensor, long ts, boolean failure) {}

    @TempDir
    Path state;

    static List<Reading> robot(String robot, BiPredicate<String, Long> fault) {
        List<Reading> out = new ArrayList<>();
        for (long offset = 0; offset < 9000; offset += 100) {
            for (Object[] s : new Object[][] {{"ir", 0L}, {"kidnap", 30L}, {"hazard", 60L}}) {
                long t = offset + (Long) s[1];
                out.add(new Reading(robot, (String) s[0], T0 + t, fault.test((String) s[0], t)));
            }
        }
        return out;
    }

    @Test
    void pickedUpLongerThanTheWindowTurnsRedThenGreenAndNothingElseHappens() {
        Settings settings = new Settings("unused:9092", "http://unused/apis/registry/v3", 2000, 1000, "test",
                state, true, RuleConfig.defaults(), Topics.defaults(), false);
        ValueSerdes serdes = new ValueSerdes(PlainAvroSerde.of(IrIntensityVector.class),
                PlainAvroSerde.of(HazardDetectionVector.class), PlainAvroSerde.of(KidnapStatus.class),
                PlainAvroSerde.of(LightringLeds.class));
        List<String> told = new ArrayList<>();
        Properties props = Main.properties(settings);
        props.put(StreamsConfig.STATE_DIR_CONFIG, state.toString());
        // the test driver commits after every record: RocksDB would flush 800 times
        props.put(StreamsConfig.DSL_STORE_SUPPLIERS_CLASS_CONFIG, BuiltInDslStoreSuppliers.InMemoryDslStoreSuppliers.class);

        List<Reading> timeline = new ArrayList<>();
        timeline.addAll(robot("tb4_01", (s, t) -> false));
        timeline.addAll(robot("tb4_02", (s, t) -> t >= 2000 && t < 5500));
        timeline.addAll(robot("tb4_03", (s, t) -> s.equals("kidnap") && t == 4030));
        timeline.sort(Comparator.comparingLong(Reading::ts));

        try (TopologyTestDriver driver = new TopologyTestDriver(FaultDetectionTopology.build(settings, serdes,
                (command, previous, window) -> told.add(command.robot() + ":" + previous + "->" + command.state()),
                Stores.inMemoryKeyValueStore(FaultDetectionTopology.MEMORY_STORE)), props)) {
            Topics topics = settings.topics();
            TestInputTopic<String, IrIntensityVector> ir = driver.createInputTopic(
                    topics.irIntensity(), Serdes.String().serializer(), serdes.irIntensity().serializer());
            TestInputTopic<String, KidnapStatus> kidnap = driver.createInputTopic(
                    topics.kidnapStatus(), Serdes.String().serializer(), serdes.kidnapStatus().serializer());
            TestInputTopic<String, HazardDetectionVector> hazard = driver.createInputTopic(
                    topics.hazardDetection(), Serdes.String().serializer(), serdes.hazardDetection().serializer());
            for (Reading r : timeline) {
                Instant at = Instant.ofEpochMilli(r.ts());
                switch (r.sensor()) {
                    case "ir" -> ir.pipeInput(r.robot(), RulesTest.ir(r.failure() ? PICKED_UP_IR : HEALTHY_IR), at);
                    case "kidnap" -> kidnap.pipeInput(r.robot(), KidnapStatus.newBuilder()
                            .setHeader(RulesTest.HEADER).setIsKidnapped(r.failure()).build(), at);
                    default -> hazard.pipeInput(r.robot(),
                            r.failure() ? RulesTest.hazards(1, RuleConfig.HAZARD_WHEEL_DROP) : RulesTest.hazards(1), at);
                }
            }
            TestOutputTopic<String, LightringLeds> commands = driver.createOutputTopic(
                    topics.commands(), Serdes.String().deserializer(), serdes.commands().deserializer());
            List<TestRecord<String, LightringLeds>> out = commands.readRecordsToList();

            assertEquals(List.of("tb4_02:running->failed", "tb4_02:failed->running"), told);
            assertEquals(2, out.size());
            assertEquals(List.of("tb4_02", "tb4_02"), out.stream().map(TestRecord::key).toList());
            assertEquals(List.of(T0 + 4000, T0 + 7500), out.stream().map(TestRecord::timestamp).toList());
            assertEquals(List.of("tb4_02-failed-" + (T0 + 4000), "tb4_02-running-" + (T0 + 7500)),
                    out.stream().map(r -> new String(r.headers().lastHeader(Decide.COMMAND_ID_HEADER).value(), UTF_8)).toList());
            assertEquals(List.of(255, 0), out.stream().map(r -> r.value().getLeds().get(0).getRed()).toList());
            assertEquals(List.of(0, 255), out.stream().map(r -> r.value().getLeds().get(0).getGreen()).toList());
        }
    }
}
