package fleetlink.faultdetection;

import java.util.function.Predicate;
import org.apache.kafka.streams.processor.api.ContextualFixedKeyProcessor;
import org.apache.kafka.streams.processor.api.FixedKeyRecord;

/** Sensor record → {@link Event} (failure or healthy, with the record's timestamp); keyless or empty records are dropped. */
final class Classify<V> extends ContextualFixedKeyProcessor<String, V, Event> {
    private final Sensor sensor;
    private final Predicate<V> failure;

    Classify(Sensor sensor, Predicate<V> failure) {
        this.sensor = sensor;
        this.failure = failure;
    }

    @Override
    public void process(FixedKeyRecord<String, V> record) {
        if (record.key() == null || record.value() == null) {
            return; // no robot to judge, or a tombstone: nothing to say
        }
        context().forward(record.withValue(new Event(sensor, failure.test(record.value()), record.timestamp())));
    }
}
