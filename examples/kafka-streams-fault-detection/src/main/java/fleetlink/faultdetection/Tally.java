package fleetlink.faultdetection;

/**
 * The aggregate of one sliding window: how many events, how many say failure, the newest stamp.
 *
 * @param events events in the window
 * @param failures events that say failure
 * @param newestMs the newest event timestamp in the window ({@link Long#MIN_VALUE} when empty)
 */
public record Tally(long events, long failures, long newestMs) {
    public static final Tally EMPTY = new Tally(0, 0, Long.MIN_VALUE);

    public Tally add(Event event) {
        return new Tally(events + 1, failures + (event.failure() ? 1 : 0), Math.max(newestMs, event.timestampMs()));
    }
}
