package fleetlink.faultdetection;

import java.nio.ByteBuffer;
import org.apache.kafka.common.errors.SerializationException;
import org.apache.kafka.common.serialization.Serde;
import org.apache.kafka.common.serialization.Serdes;

/**
 * Fixed-size binary serdes for what the app keeps in its state stores (and their changelogs):
 * the window aggregate ({@link Tally}, 24 bytes) and a robot's memory ({@link RobotMemory}, 9 bytes).
 * Anything of another size is a broken store and raises.
 */
public final class StateSerdes {
    private static final int TALLY_BYTES = 3 * Long.BYTES;
    private static final int MEMORY_BYTES = 1 + Long.BYTES;

    private StateSerdes() {}

    public static Serde<Tally> tally() {
        return Serdes.serdeFrom(
                (topic, tally) -> tally == null ? null : ByteBuffer.allocate(TALLY_BYTES)
                        .putLong(tally.events()).putLong(tally.failures()).putLong(tally.newestMs()).array(),
                (topic, bytes) -> {
                    if (bytes == null) {
                        return null;
                    }
                    ByteBuffer buf = exactly(bytes, TALLY_BYTES, "window tally");
                    return new Tally(buf.getLong(), buf.getLong(), buf.getLong());
                });
    }

    public static Serde<RobotMemory> memory() {
        return Serdes.serdeFrom(
                (topic, memory) -> memory == null ? null : ByteBuffer.allocate(MEMORY_BYTES)
                        .put((byte) memory.state().ordinal()).putLong(memory.lastWindowEndMs()).array(),
                (topic, bytes) -> {
                    if (bytes == null) {
                        return null;
                    }
                    ByteBuffer buf = exactly(bytes, MEMORY_BYTES, "robot memory");
                    int ordinal = buf.get();
                    RobotState[] states = RobotState.values();
                    if (ordinal < 0 || ordinal >= states.length) {
                        throw new SerializationException("corrupt robot memory: unknown state " + ordinal);
                    }
                    return new RobotMemory(states[ordinal], buf.getLong());
                });
    }

    private static ByteBuffer exactly(byte[] bytes, int size, String what) {
        if (bytes.length != size) {
            throw new SerializationException("corrupt " + what + ": " + bytes.length + " bytes, expected " + size);
        }
        return ByteBuffer.wrap(bytes);
    }
}
