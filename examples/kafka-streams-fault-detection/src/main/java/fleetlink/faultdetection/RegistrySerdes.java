package fleetlink.faultdetection;

import io.apicurio.registry.serde.avro.AvroSerde;
import java.util.Map;
import org.apache.avro.specific.SpecificRecord;
import org.apache.kafka.common.serialization.Serde;

/**
 * Avro serdes through the Apicurio Registry, reading and writing what fleetlink writes: the
 * Confluent wire format (byte 0, 4-byte big-endian schema id, Avro binary body), the id being the
 * one the registry's Confluent-compatible API hands out (Apicurio's content id).
 *
 * <p>Apicurio's 3.x serde speaks the registry's <em>native</em> API only: its URL is
 * {@code http://HOST:PORT/apis/registry/v3}; the {@code /apis/ccompat/v7} URL that Confluent
 * clients take answers it with a bare 404.
 */
public final class RegistrySerdes {
    private RegistrySerdes() {}

    /** The settings, spelled out (most are the 3.1 defaults; they are what makes the format match). */
    public static Map<String, Object> config(String nativeUrl) {
        return Map.of(
                // the native API (v3), not the Confluent-compatible one
                "apicurio.registry.url", nativeUrl,
                // the schema id in the value (magic byte 0 + id), not in Kafka headers
                "apicurio.registry.headers.enabled", false,
                // 4-byte ids (Confluent's size), not the legacy 8-byte ones
                "apicurio.registry.id-handler", "io.apicurio.registry.serde.Default4ByteIdHandler",
                // the id ccompat hands out and fleetlink writes is the content id
                "apicurio.registry.use-id", "contentId",
                // values as the generated classes (SpecificRecord), resolved writer → reader schema
                "apicurio.registry.use-specific-avro-reader", true,
                // commands: register the class's schema under <topic>-value unless an equal one is there,
                "apicurio.registry.auto-register", true,
                "apicurio.registry.auto-register.if-exists", "FIND_OR_CREATE_VERSION",
                // whole, as fleetlink registers its schemas: not its nested records as separate
                // artifacts referenced by name (the default), which Confluent-style readers
                // (fleetlink's uplink among them) cannot resolve
                "apicurio.registry.dereference-schema", true);
    }

    /** A value serde for the generated class {@code T}. */
    public static <T extends SpecificRecord> Serde<T> forValues(String nativeUrl) {
        AvroSerde<T> serde = new AvroSerde<>();
        serde.configure(config(nativeUrl), false);
        return serde;
    }
}
