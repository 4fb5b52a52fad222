package fleetlink.faultdetection;

/** The app cannot start (Kafka unreachable, sensor topics not co-partitioned ...): exit code 1. */
public final class StartupException extends Exception {
    private static final long serialVersionUID = 1L;

    public StartupException(String message) {
        super(message);
    }

    public StartupException(String message, Throwable cause) {
        super(message, cause);
    }
}
