package fleetlink.faultdetection;

import java.util.List;

/** Kafka topics the app reads (one per sensor) and writes (light-ring commands). */
public record Topics(String irIntensity, String hazardDetection, String kidnapStatus, String commands) {
    public static Topics defaults() {
        return new Topics("fleet.ir_intensity", "fleet.hazard_detection", "fleet.kidnap_status", "fleet.commands.lightring");
    }

    public List<String> sensors() {
        return List.of(irIntensity, hazardDetection, kidnapStatus);
    }
}
