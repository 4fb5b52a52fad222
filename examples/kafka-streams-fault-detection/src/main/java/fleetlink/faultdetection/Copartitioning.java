package fleetlink.faultdetection;

import java.util.Map;
import java.util.TreeMap;
import java.util.stream.Collectors;

/**
 * The sensor topics that exist must share one partition count: a robot's windows and state live
 * in the partition its key hashes to, so its IR, hazard and kidnap records must land in the same
 * partition number (pure).
 */
public final class Copartitioning {
    private Copartitioning() {}

    /** Refuse different counts; otherwise the count the missing sensor topics get (empty: the broker's default). */
    public static java.util.OptionalInt check(Map<String, Integer> existing) throws StartupException {
        if (existing.values().stream().distinct().count() > 1) {
            String listing = new TreeMap<>(existing).entrySet().stream()
                    .map(e -> e.getKey() + "=" + e.getValue())
                    .collect(Collectors.joining(", "));
            throw new StartupException("the sensor topics must have the same number of partitions (a robot's records "
                    + "must meet in one partition), got " + listing);
        }
        return existing.values().stream().mapToInt(Integer::intValue).findFirst();
    }
}
