package fleetlink.faultdetection;

import org.apache.kafka.common.serialization.Serde;
import ros.irobot_create_msgs.msg.HazardDetectionVector;
import ros.irobot_create_msgs.msg.IrIntensityVector;
import ros.irobot_create_msgs.msg.KidnapStatus;
import ros.irobot_create_msgs.msg.LightringLeds;

/** The value serdes of the four topics (the registry's in the app; plain Avro in tests). */
public record ValueSerdes(
        Serde<IrIntensityVector> irIntensity,
        Serde<HazardDetectionVector> hazardDetection,
        Serde<KidnapStatus> kidnapStatus,
        Serde<LightringLeds> commands) {
    public static ValueSerdes registry(String nativeUrl) {
        return new ValueSerdes(
                RegistrySerdes.forValues(nativeUrl),
                RegistrySerdes.forValues(nativeUrl),
                RegistrySerdes.forValues(nativeUrl),
                RegistrySerdes.forValues(nativeUrl));
    }
}
