package fleetlink.faultdetection;

import java.util.Map;
import java.util.concurrent.atomic.AtomicLong;
import org.apache.kafka.clients.consumer.ConsumerRecord;
import org.apache.kafka.streams.errors.DeserializationExceptionHandler;
import org.apache.kafka.streams.errors.ErrorHandlerContext;
import org.slf4j.Logger;
import org.slf4j.LoggerFactory;

/**
 * Undecodable records (not the Confluent framing, an unknown schema id, a writer schema that does
 * not resolve to the generated class) are skipped: the first logged in full, then one line every
 * {@value #EVERY}; the app keeps going.
 */
public final class SkipUndecodable implements DeserializationExceptionHandler {
    static final int EVERY = 100;
    private static final Logger LOG = LoggerFactory.getLogger(SkipUndecodable.class);
    private static final AtomicLong SKIPPED = new AtomicLong();

    @Override
    public Response handleError(ErrorHandlerContext context, ConsumerRecord<byte[], byte[]> record, Exception exception) {
        long count = SKIPPED.incrementAndGet();
        String where = "topic=" + record.topic() + " partition=" + record.partition() + " offset=" + record.offset();
        if (count == 1) {
            LOG.warn("skipping undecodable record {} (further ones counted, logged every {})", where, EVERY, exception);
        } else if (count % EVERY == 0) {
            LOG.warn("{} undecodable records skipped so far; latest: {} error={}", count, where, exception.toString());
        }
        return Response.resume();
    }

    @Override
    public void configure(Map<String, ?> configs) {}

    /** How many records were skipped since the process started. */
    public static long skipped() {
        return SKIPPED.get();
    }
}
