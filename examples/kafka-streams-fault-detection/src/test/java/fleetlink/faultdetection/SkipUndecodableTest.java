package fleetlink.faultdetection;

import static org.junit.jupiter.api.Assertions.assertEquals;

import org.junit.jupiter.api.Test;

class SkipUndecodableTest {
    @Test
    void reasonsNameTheWireFormat() {
        Exception vague = new IllegalStateException("artifact reference cannot be null");
        assertEquals("not the Confluent wire format: magic byte 0x6e is not 0x00",
                SkipUndecodable.reason("not avro".getBytes(java.nio.charset.StandardCharsets.US_ASCII), vague));
        assertEquals("3 bytes are too short for the Confluent header (magic byte + 4-byte schema id)",
                SkipUndecodable.reason(new byte[3], vague));
        assertEquals(vague.toString(), SkipUndecodable.reason(new byte[] {0, 0, 0, 0, 42, 1}, vague));
    }
}
