package fleetlink.faultdetection;

import java.time.Duration;
import org.apache.kafka.common.serialization.Serdes;
import org.apache.kafka.common.utils.Bytes;
import org.apache.kafka.streams.StreamsBuilder;
import org.apache.kafka.streams.Topology;
import org.apache.kafka.streams.kstream.Consumed;
import org.apache.kafka.streams.kstream.Grouped;
import org.apache.kafka.streams.kstream.KStream;
import org.apache.kafka.streams.kstream.Materialized;
import org.apache.kafka.streams.kstream.Named;
import org.apache.kafka.streams.kstream.Produced;
import org.apache.kafka.streams.kstream.SlidingWindows;
import org.apache.kafka.streams.state.KeyValueBytesStoreSupplier;
import org.apache.kafka.streams.state.Stores;
import org.apache.kafka.streams.state.WindowStore;

/**
 * The pipeline: three sensor topics in, light-ring commands out.
 *
 * <pre>
 * fleet.ir_intensity ─────┐  event → failure
 * fleet.hazard_detection ─┼─ (Rules) ─ merge ─ sliding window per robot
 * fleet.kidnap_status ────┘                     (events, failures, newest)
 *                                                       │
 * fleet.commands.lightring ◀─ Avro (registry) ◀─ command on change ◀┘
 *                                                (state store robot-memory)
 * </pre>
 *
 * Windows follow the record timestamps (the robots' ROS stamps): decisions follow event time.
 */
public final class FaultDetectionTopology {
    public static final String WINDOW_STORE = "fault-windows";
    public static final String MEMORY_STORE = "robot-memory";

    private FaultDetectionTopology() {}

    public static Topology build(Settings settings, ValueSerdes serdes, CommandListener listener) {
        return build(settings, serdes, listener, Stores.persistentKeyValueStore(MEMORY_STORE));
    }

    /** With another store for the robots' memories (tests use an in-memory one, with {@code dsl.store.suppliers.class} to match). */
    public static Topology build(
            Settings settings, ValueSerdes serdes, CommandListener listener, KeyValueBytesStoreSupplier memoryStore) {
        RuleConfig rules = settings.rules();
        Topics topics = settings.topics();
        StreamsBuilder builder = new StreamsBuilder();

        KStream<String, Event> ir = builder
                .stream(topics.irIntensity(), Consumed.with(Serdes.String(), serdes.irIntensity()).withName("ir-intensity"))
                .processValues(() -> new Classify<>(Sensor.IR_INTENSITY, v -> Rules.irFailure(v, rules.irThreshold())),
                        Named.as("classify-ir-intensity"));
        KStream<String, Event> hazards = builder
                .stream(topics.hazardDetection(), Consumed.with(Serdes.String(), serdes.hazardDetection()).withName("hazard-detection"))
                .processValues(() -> new Classify<>(Sensor.HAZARD_DETECTION, v -> Rules.hazardFailure(v, rules.failureHazards())),
                        Named.as("classify-hazard-detection"));
        KStream<String, Event> kidnap = builder
                .stream(topics.kidnapStatus(), Consumed.with(Serdes.String(), serdes.kidnapStatus()).withName("kidnap-status"))
                .processValues(() -> new Classify<>(Sensor.KIDNAP_STATUS, Rules::kidnapFailure),
                        Named.as("classify-kidnap-status"));

        builder.addStateStore(Stores.keyValueStoreBuilder(
                memoryStore, Serdes.String(), StateSerdes.memory()));

        ir.merge(hazards, Named.as("merge-hazards"))
                .merge(kidnap, Named.as("merge-kidnap"))
                .groupByKey(Grouped.as("by-robot"))
                .windowedBy(SlidingWindows.ofTimeDifferenceAndGrace(
                        Duration.ofMillis(settings.windowMs()), Duration.ofMillis(settings.graceMs())))
                .aggregate(
                        () -> Tally.EMPTY,
                        (robot, event, tally) -> tally.add(event),
                        Named.as("tally"),
                        Materialized.<String, Tally, WindowStore<Bytes, byte[]>>as(WINDOW_STORE)
                                .withKeySerde(Serdes.String())
                                .withValueSerde(StateSerdes.tally())
                                // every update of a window goes downstream, none held back in a cache
                                .withCachingDisabled())
                .toStream(Named.as("windows"))
                .process(() -> new Decide(MEMORY_STORE, rules.minEvents(), listener), Named.as("decide"), MEMORY_STORE)
                .to(topics.commands(), Produced.with(Serdes.String(), serdes.commands()).withName("commands"));
        return builder.build();
    }
}
