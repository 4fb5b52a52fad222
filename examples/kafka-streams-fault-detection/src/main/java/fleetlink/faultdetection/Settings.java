package fleetlink.faultdetection;

import java.nio.file.Path;

/**
 * Everything the app needs, as the command line gave it.
 *
 * @param bootstrap Kafka bootstrap servers, HOST:PORT[,...]
 * @param registryUrl the Apicurio Registry's native API, {@code http://HOST:PORT/apis/registry/v3}
 * @param windowMs sliding window length
 * @param graceMs how late a record may arrive and still count
 * @param group the Kafka Streams application.id (consumer group, prefix of internal topics)
 * @param stateDir the state store folder
 * @param fromBeginning a new group starts at the earliest records (else the latest)
 * @param rules thresholds of the rules
 * @param topics input and output topics
 * @param verbose log more
 */
public record Settings(
        String bootstrap,
        String registryUrl,
        long windowMs,
        long graceMs,
        String group,
        Path stateDir,
        boolean fromBeginning,
        RuleConfig rules,
        Topics topics,
        boolean verbose) {
    public static final String DEFAULT_GROUP = "fleetlink-fault-detection-java";

    public static Path defaultStateDir() {
        return Path.of(System.getProperty("user.home"), ".cache", "fleetlink", "fault-detection-java");
    }
}
