package fleetlink.faultdetection;

import java.nio.file.Path;
import java.util.HashMap;
import java.util.HashSet;
import java.util.Locale;
import java.util.Map;
import java.util.Set;
import java.util.regex.Matcher;
import java.util.regex.Pattern;

/** The command line, parsed into {@link Settings} (pure: no environment, no network). */
public final class Options {
    public static final String USAGE = String.join("\n",
            "usage: java -jar kafka-streams-fault-detection.jar --bootstrap HOST:PORT --registry URL [options]",
            "",
            "Fault detection over the fleet's sensor topics on Kafka Streams: a sliding window per robot;",
            "when every event in it says failure the robot is failed (red light ring), when every event",
            "says healthy it runs again (green). One command per change of state.",
            "",
            "  --bootstrap HOST:PORT     Kafka bootstrap servers (also -b)",
            "  --registry URL            Apicurio Registry native API, http://HOST:PORT/apis/registry/v3",
            "                            (not the Confluent-compatible /apis/ccompat/v7 URL)",
            "  --window DURATION         sliding window length, e.g. 2s, 500ms (default: 2s)",
            "  --grace DURATION          how late a record may arrive and still count (default: 1s)",
            "  --group ID                application.id = consumer group (default: " + Settings.DEFAULT_GROUP + ")",
            "  --state-dir DIR           state store folder (default: ~/.cache/fleetlink/fault-detection-java)",
            "  --from-beginning          a new group starts at the earliest records (default: the latest)",
            "  --ir-threshold N          IR readings all above this mean picked up (default: 3000)",
            "  --failure-hazards N[,N]   HazardDetection types that mean failure (default: 2,4)",
            "  --min-events N            fewer events in a window never change the state (default: 2)",
            "  --ir-topic, --hazard-topic, --kidnap-topic, --commands-topic NAME",
            "                            topics (default: fleet.ir_intensity, fleet.hazard_detection,",
            "                            fleet.kidnap_status, fleet.commands.lightring)",
            "  -v, --verbose             log more (Kafka Streams' own INFO lines)",
            "  -h, --help                this text");

    private static final Set<String> FLAGS = Set.of("--from-beginning", "-v", "--verbose", "-h", "--help");
    private static final Set<String> VALUED = Set.of(
            "--bootstrap", "-b", "--registry", "--window", "--grace", "--group", "--state-dir",
            "--ir-threshold", "--failure-hazards", "--min-events",
            "--ir-topic", "--hazard-topic", "--kidnap-topic", "--commands-topic");
    private static final Pattern DURATION = Pattern.compile("^(\\d+(?:\\.\\d+)?)\\s*(ms|s|m)?$");
    private static final String CCOMPAT = "/apis/ccompat/";
    private static final String NATIVE = "/apis/registry/v3";

    private Options() {}

    /** Whether the arguments ask for the usage text. */
    public static boolean wantsHelp(String[] args) {
        for (String arg : args) {
            if (arg.equals("-h") || arg.equals("--help")) {
                return true;
            }
        }
        return false;
    }

    public static Settings parse(String[] args) throws UsageException {
        Map<String, String> values = new HashMap<>();
        Set<String> flags = new HashSet<>();
        for (int i = 0; i < args.length; i++) {
            String arg = args[i];
            String name = arg;
            String value = null;
            int eq = arg.indexOf('=');
            if (arg.startsWith("--") && eq > 0) {
                name = arg.substring(0, eq);
                value = arg.substring(eq + 1);
            }
            if (FLAGS.contains(name) && value == null) {
                flags.add(name);
            } else if (VALUED.contains(name)) {
                if (value == null) {
                    if (i + 1 >= args.length) {
                        throw new UsageException(name + " needs a value");
                    }
                    value = args[++i];
                }
                values.put(name.equals("-b") ? "--bootstrap" : name, value);
            } else {
                throw new UsageException("unknown option " + arg);
            }
        }
        String bootstrap = required(values, "--bootstrap");
        String registry = registryUrl(required(values, "--registry"));
        Topics defaults = Topics.defaults();
        RuleConfig ruleDefaults = RuleConfig.defaults();
        RuleConfig rules = new RuleConfig(
                integer(values, "--ir-threshold", ruleDefaults.irThreshold()),
                values.containsKey("--failure-hazards") ? hazards(values.get("--failure-hazards")) : ruleDefaults.failureHazards(),
                positive(values, "--min-events", ruleDefaults.minEvents()));
        long window = durationMs(values.getOrDefault("--window", "2s"), "--window");
        long grace = values.containsKey("--grace") ? durationMs(values.get("--grace"), "--grace") : 1000;
        return new Settings(
                bootstrap,
                registry,
                window,
                grace,
                nonEmpty(values.getOrDefault("--group", Settings.DEFAULT_GROUP), "--group"),
                values.containsKey("--state-dir") ? Path.of(values.get("--state-dir")) : Settings.defaultStateDir(),
                flags.contains("--from-beginning"),
                rules,
                new Topics(
                        nonEmpty(values.getOrDefault("--ir-topic", defaults.irIntensity()), "--ir-topic"),
                        nonEmpty(values.getOrDefault("--hazard-topic", defaults.hazardDetection()), "--hazard-topic"),
                        nonEmpty(values.getOrDefault("--kidnap-topic", defaults.kidnapStatus()), "--kidnap-topic"),
                        nonEmpty(values.getOrDefault("--commands-topic", defaults.commands()), "--commands-topic")),
                flags.contains("-v") || flags.contains("--verbose"));
    }

    /**
     * {@code "2s"} → 2000, {@code "500ms"} → 500, {@code "1.5s"} → 1500, {@code "1m"} → 60000; a bare
     * number is seconds. The result must be a positive whole number of milliseconds.
     */
    public static long durationMs(String text, String option) throws UsageException {
        Matcher m = DURATION.matcher(text.trim().toLowerCase(Locale.ROOT));
        if (!m.matches()) {
            throw new UsageException(option + ": invalid duration '" + text + "'; e.g. 2s, 500ms, 1.5s or 1m");
        }
        double number = Double.parseDouble(m.group(1));
        String unit = m.group(2) == null ? "s" : m.group(2);
        double ms = switch (unit) {
            case "ms" -> number;
            case "m" -> number * 60_000;
            default -> number * 1000;
        };
        if (ms <= 0 || ms != Math.rint(ms)) {
            throw new UsageException(option + ": '" + text + "' is not a positive whole number of milliseconds");
        }
        return (long) ms;
    }

    /** The registry URL, refused with the right one when it is the Confluent-compatible API's. */
    public static String registryUrl(String url) throws UsageException {
        String trimmed = url.replaceAll("/+$", "");
        int at = trimmed.indexOf(CCOMPAT);
        if (at >= 0) {
            throw new UsageException("--registry " + url + " is the registry's Confluent-compatible API; the Apicurio "
                    + "serde talks to its native API: --registry " + trimmed.substring(0, at) + NATIVE);
        }
        if (!trimmed.startsWith("http://") && !trimmed.startsWith("https://")) {
            throw new UsageException("--registry must be an http(s) URL, e.g. http://127.0.0.1:8081" + NATIVE + ", got " + url);
        }
        return trimmed;
    }

    static Set<Integer> hazards(String text) throws UsageException {
        Set<Integer> out = new HashSet<>();
        for (String part : text.split(",")) {
            if (part.isBlank()) {
                continue;
            }
            try {
                out.add(Integer.parseInt(part.trim()));
            } catch (NumberFormatException e) {
                throw new UsageException("--failure-hazards: expected comma-separated hazard type numbers, got '" + text + "'");
            }
        }
        return out;
    }

    private static String required(Map<String, String> values, String name) throws UsageException {
        return nonEmpty(values.get(name), name);
    }

    private static String nonEmpty(String value, String name) throws UsageException {
        if (value == null || value.isBlank()) {
            throw new UsageException(name + " is required");
        }
        return value;
    }

    private static int integer(Map<String, String> values, String name, int fallback) throws UsageException {
        String text = values.get(name);
        if (text == null) {
            return fallback;
        }
        try {
            return Integer.parseInt(text.trim());
        } catch (NumberFormatException e) {
            throw new UsageException(name + ": expected a whole number, got '" + text + "'");
        }
    }

    private static int positive(Map<String, String> values, String name, int fallback) throws UsageException {
        int value = integer(values, name, fallback);
        if (value < 1) {
            throw new UsageException(name + " must be at least 1, got " + value);
        }
        return value;
    }
}
