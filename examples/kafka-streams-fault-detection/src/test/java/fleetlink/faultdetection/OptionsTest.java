package fleetlink.faultdetection;

import static org.junit.jupiter.api.Assertions.assertEquals;
import static org.junit.jupiter.api.Assertions.assertFalse;
import static org.junit.jupiter.api.Assertions.assertThrows;
import static org.junit.jupiter.api.Assertions.assertTrue;

import java.nio.file.Path;
import java.util.Map;
import java.util.OptionalInt;
import java.util.Set;
import org.junit.jupiter.api.Test;
import org.junit.jupiter.params.ParameterizedTest;
import org.junit.jupiter.params.provider.CsvSource;
import org.junit.jupiter.params.provider.ValueSource;

class OptionsTest {
    static final String NATIVE = "http://127.0.0.1:8081/apis/registry/v3";

    @Test
    void defaultsMirrorThePythonApp() throws UsageException {
        Settings s = Options.parse(new String[] {"--bootstrap", "127.0.0.1:9092", "--registry", NATIVE});
        assertEquals("127.0.0.1:9092", s.bootstrap());
        assertEquals(NATIVE, s.registryUrl());
        assertEquals(2000, s.windowMs());
        assertEquals(1000, s.graceMs());
        assertEquals(Settings.DEFAULT_GROUP, s.group());
        assertFalse(s.fromBeginning());
        assertEquals(RuleConfig.defaults(), s.rules());
        assertEquals(Topics.defaults(), s.topics());
    }

    @Test
    void everyOptionIsRead() throws UsageException {
        Settings s = Options.parse(new String[] {
            "-b", "k:1", "--registry=" + NATIVE + "/", "--window", "500ms", "--grace=0.5s", "--group", "g",
            "--state-dir", "st", "--from-beginning", "--ir-threshold", "100", "--failure-hazards", "1, 2",
            "--min-events", "3", "--ir-topic", "a", "--hazard-topic", "b", "--kidnap-topic", "c",
            "--commands-topic", "d", "-v"});
        assertEquals("k:1", s.bootstrap());
        assertEquals(NATIVE, s.registryUrl());
        assertEquals(500, s.windowMs());
        assertEquals(500, s.graceMs());
        assertEquals("g", s.group());
        assertEquals(Path.of("st"), s.stateDir());
        assertTrue(s.fromBeginning());
        assertEquals(new RuleConfig(100, Set.of(1, 2), 3), s.rules());
        assertEquals(new Topics("a", "b", "c", "d"), s.topics());
        assertTrue(s.verbose());
    }

    @ParameterizedTest
    @CsvSource({"2s, 2000", "500ms, 500", "1.5s, 1500", "1m, 60000", "3, 3000", "0.25, 250"})
    void durations(String text, long ms) throws UsageException {
        assertEquals(ms, Options.durationMs(text, "--window"));
    }

    @ParameterizedTest
    @ValueSource(strings = {"0s", "-1s", "2h", "abc", "0.5ms", ""})
    void badDurationsAreRefused(String text) {
        assertThrows(UsageException.class, () -> Options.durationMs(text, "--window"));
    }

    @Test
    void theConfluentCompatibleUrlIsRefusedNamingTheNativeOne() {
        UsageException e = assertThrows(UsageException.class,
                () -> Options.registryUrl("http://127.0.0.1:8081/apis/ccompat/v7"));
        assertTrue(e.getMessage().contains("--registry " + NATIVE), e.getMessage());
    }

    @Test
    void missingOrUnknownOptionsAreRefused() {
        assertThrows(UsageException.class, () -> Options.parse(new String[] {"--registry", NATIVE}));
        assertThrows(UsageException.class, () -> Options.parse(new String[] {"-b", "k:1"}));
        assertThrows(UsageException.class, () -> Options.parse(new String[] {"-b", "k:1", "--registry", NATIVE, "--nope"}));
        assertThrows(UsageException.class, () -> Options.parse(new String[] {"-b", "k:1", "--registry", NATIVE, "--window"}));
        assertThrows(UsageException.class, () -> Options.parse(new String[] {"-b", "k:1", "--registry", NATIVE, "--min-events", "0"}));
        assertThrows(UsageException.class, () -> Options.parse(new String[] {"-b", "k:1", "--registry", NATIVE, "--failure-hazards", "x"}));
        assertThrows(UsageException.class, () -> Options.parse(new String[] {"-b", "k:1", "--registry", "127.0.0.1:8081"}));
    }

    @Test
    void sensorTopicsMustShareOnePartitionCount() throws StartupException {
        assertEquals(OptionalInt.empty(), Copartitioning.check(Map.of()));
        assertEquals(OptionalInt.of(3), Copartitioning.check(Map.of("a", 3, "b", 3)));
        StartupException e = assertThrows(StartupException.class, () -> Copartitioning.check(Map.of("a", 3, "b", 1)));
        assertTrue(e.getMessage().contains("a=3, b=1"), e.getMessage());
    }
}
