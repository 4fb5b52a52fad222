package fleetlink.faultdetection;

import java.util.Set;

/**
 * The tunable parts of the rules.
 *
 * @param irThreshold an IR reading strictly above this covers the sensor (default 3000)
 * @param failureHazards hazard types that mean "picked up" (default WHEEL_DROP = 4, CLIFF = 2)
 * @param minEvents a window with fewer events decides nothing (default 2)
 */
public record RuleConfig(int irThreshold, Set<Integer> failureHazards, int minEvents) {
    public static final int HAZARD_CLIFF = 2;
    public static final int HAZARD_WHEEL_DROP = 4;

    public RuleConfig {
        failureHazards = Set.copyOf(failureHazards);
        if (minEvents < 1) {
            throw new IllegalArgumentException("minEvents must be at least 1, got " + minEvents);
        }
    }

    public static RuleConfig defaults() {
        return new RuleConfig(3000, Set.of(HAZARD_WHEEL_DROP, HAZARD_CLIFF), 2);
    }
}
