package fleetlink.faultdetection;

/** Invalid command-line options; the message says which and how to fix it (exit code 2). */
public final class UsageException extends Exception {
    private static final long serialVersionUID = 1L;

    public UsageException(String message) {
        super(message);
    }
}
