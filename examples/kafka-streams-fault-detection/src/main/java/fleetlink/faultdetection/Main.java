package fleetlink.faultdetection;

import java.io.PrintStream;
import java.time.Duration;
import java.util.Properties;
import java.util.concurrent.CountDownLatch;
import java.util.concurrent.atomic.AtomicBoolean;
import java.util.concurrent.atomic.AtomicInteger;
import org.apache.kafka.clients.consumer.ConsumerConfig;
import org.apache.kafka.streams.KafkaStreams;
import org.apache.kafka.streams.StreamsConfig;
import org.apache.kafka.streams.errors.StreamsUncaughtExceptionHandler.StreamThreadExceptionResponse;
import org.slf4j.Logger;
import org.slf4j.LoggerFactory;

/**
 * {@code java -jar kafka-streams-fault-detection.jar --bootstrap HOST:PORT --registry URL ...}
 *
 * <p>Exit codes: 0 after SIGINT/SIGTERM (finish the record in hand, commit, close); 2 for invalid
 * options; 1 when it cannot start or a stream thread fails.
 */
public final class Main {
    static final long CLOSE_TIMEOUT_S = 15;
    /** Held so the level sticks: java.util.logging keeps loggers only weakly. */
    private static final java.util.logging.Logger APICURIO_JUL = java.util.logging.Logger.getLogger("io.apicurio");

    private Main() {}

    public static void main(String[] args) {
        System.exit(run(args, System.out, System.err));
    }

    static int run(String[] args, PrintStream out, PrintStream err) {
        if (Options.wantsHelp(args)) {
            out.println(Options.USAGE);
            return 0;
        }
        Settings settings;
        try {
            settings = Options.parse(args);
        } catch (UsageException e) {
            err.println("error: " + e.getMessage());
            err.println("(--help lists the options)");
            return 2;
        }
        // slf4j-simple reads its levels when the first logger is made: Kafka's own INFO lines only with -v
        System.setProperty("org.slf4j.simpleLogger.log.org.apache.kafka", settings.verbose() ? "info" : "warn");
        // the registry client's advice about its shared Vert.x instance is for embedders, not this app
        APICURIO_JUL.setLevel(settings.verbose() ? java.util.logging.Level.INFO : java.util.logging.Level.SEVERE);
        Logger log = LoggerFactory.getLogger(Main.class);
        try {
            TopicSetup.ensure(settings.bootstrap(), settings.topics());
        } catch (StartupException e) {
            err.println("error: " + e.getMessage());
            return 1;
        }
        CommandListener tell = (command, previous, window) -> log.info(
                "robot={} state={}->{} window_end_ms={} events={} failures={} command_id={}",
                command.robot(), previous, command.state(), command.stampMs(), window.events(), window.failures(),
                command.commandId());
        KafkaStreams streams = new KafkaStreams(
                FaultDetectionTopology.build(settings, ValueSerdes.registry(settings.registryUrl()), tell),
                properties(settings));
        return runUntilStopped(streams, settings, log);
    }

    static Properties properties(Settings settings) {
        Properties props = new Properties();
        props.put(StreamsConfig.APPLICATION_ID_CONFIG, settings.group());
        props.put(StreamsConfig.BOOTSTRAP_SERVERS_CONFIG, settings.bootstrap());
        props.put(StreamsConfig.STATE_DIR_CONFIG, settings.stateDir().toString());
        // offsets, state and produced commands are committed together every second (at least once)
        props.put(StreamsConfig.COMMIT_INTERVAL_MS_CONFIG, 1000);
        props.put(StreamsConfig.STATESTORE_CACHE_MAX_BYTES_CONFIG, 0);
        props.put(StreamsConfig.DESERIALIZATION_EXCEPTION_HANDLER_CLASS_CONFIG, SkipUndecodable.class);
        props.put(StreamsConfig.consumerPrefix(ConsumerConfig.AUTO_OFFSET_RESET_CONFIG),
                settings.fromBeginning() ? "earliest" : "latest");
        return props;
    }

    private static int runUntilStopped(KafkaStreams streams, Settings settings, Logger log) {
        CountDownLatch stopped = new CountDownLatch(1);
        AtomicInteger exitCode = new AtomicInteger(0);
        AtomicBoolean announced = new AtomicBoolean(false);
        streams.setUncaughtExceptionHandler(exception -> {
            log.error("a stream thread failed; stopping", exception);
            exitCode.set(1);
            return StreamThreadExceptionResponse.SHUTDOWN_CLIENT;
        });
        streams.setStateListener((now, before) -> {
            if (now == KafkaStreams.State.RUNNING && announced.compareAndSet(false, true)) {
                log.info("running: application.id={} window={}ms grace={}ms reading {} writing {} registry {}",
                        settings.group(), settings.windowMs(), settings.graceMs(), settings.topics().sensors(),
                        settings.topics().commands(), settings.registryUrl());
            }
            if (now == KafkaStreams.State.NOT_RUNNING || now == KafkaStreams.State.ERROR) {
                stopped.countDown();
            }
        });
        AtomicBoolean signalled = new AtomicBoolean(false);
        Runtime.getRuntime().addShutdownHook(new Thread(() -> {
            // SIGTERM / SIGINT: finish the record in hand, commit, close; then exit 0, not the JVM's 143
            signalled.set(true);
            boolean closed = streams.close(Duration.ofSeconds(CLOSE_TIMEOUT_S));
            System.out.flush();
            Runtime.getRuntime().halt(closed ? exitCode.get() : 1);
        }, "fault-detection-stop"));
        streams.start();
        try {
            stopped.await();
        } catch (InterruptedException e) {
            Thread.currentThread().interrupt();
        }
        if (!signalled.get()) {
            exitCode.compareAndSet(0, 1); // stopped on its own, not asked to: something went wrong
        }
        streams.close(Duration.ofSeconds(CLOSE_TIMEOUT_S));
        return exitCode.get();
    }
}
