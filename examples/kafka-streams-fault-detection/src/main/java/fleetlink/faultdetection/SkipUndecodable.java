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
        String reason = reason(record.value(), exception);
        if (count == 1) {
            LOG.warn("skipping undecodable record {}: {} (further ones counted, logged every {})", where, reason, EVERY,
                    exception);
        } else if (count % EVERY == 0) {
            LOG.warn("{} undecodable records skipped so far; latest: {}: {}", count, where, reason);
        }
        return Response.resume();
    }

    /** Why a value did not decode, in fleetlink's terms where the serde's own words are vague. */
    static String reason(byte[] value, Exception exception) {
        if (value != null && value.length < 5) {
            return value.length + " bytes are too short for the Confluent header (magic byte + 4-byte schema id)";
        }
        if (value != null && value[0] != 0) {
            return String.format("not the Confluent wire format: magic byte 0x%02x is not 0x00", value[0] & 0xff);
        }
        return String.valueOf(exception);
    }

    @Override
    public void configure(Map<String, ?> configs) {}

    /** How many records were skipped since the process started. */
    public static long skipped() {
        return SKIPPED.get();
    }
}
