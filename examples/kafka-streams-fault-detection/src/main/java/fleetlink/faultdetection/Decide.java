package fleetlink.faultdetection;

import static java.nio.charset.StandardCharsets.UTF_8;

import java.util.Optional;
import org.apache.kafka.common.header.internals.RecordHeaders;
import org.apache.kafka.streams.kstream.Windowed;
import org.apache.kafka.streams.processor.api.ContextualProcessor;
import org.apache.kafka.streams.processor.api.ProcessorContext;
import org.apache.kafka.streams.processor.api.Record;
import org.apache.kafka.streams.state.KeyValueStore;
import ros.irobot_create_msgs.msg.LightringLeds;

/**
 * One window's tally → the robot's next memory (kept in a state store) → at most one command,
 * keyed by robot, stamped at the window end, with the {@code fleetlink-command-id} header.
 */
final class Decide extends ContextualProcessor<Windowed<String>, Tally, String, LightringLeds> {
    static final String COMMAND_ID_HEADER = "fleetlink-command-id";

    private final String storeName;
    private final int minEvents;
    private final CommandListener listener;
    private KeyValueStore<String, RobotMemory> memories;

    Decide(String storeName, int minEvents, CommandListener listener) {
        this.storeName = storeName;
        this.minEvents = minEvents;
        this.listener = listener;
    }

    @Override
    public void init(ProcessorContext<String, LightringLeds> context) {
        super.init(context);
        memories = context.getStateStore(storeName);
    }

    @Override
    public void process(Record<Windowed<String>, Tally> record) {
        Tally tally = record.value();
        long end = record.key().window().end();
        if (tally == null || !Rules.windowComplete(end, tally.newestMs())) {
            return;
        }
        String robot = record.key().key();
        RobotMemory stored = memories.get(robot);
        RobotMemory memory = stored == null ? RobotMemory.INITIAL : stored;
        Optional<RobotState> verdict = Rules.windowVerdict(tally.events(), tally.failures(), minEvents);
        Transition transition = Rules.step(robot, memory, verdict, end);
        if (!transition.memory().equals(memory)) {
            memories.put(robot, transition.memory());
        }
        transition.command().ifPresent(command -> {
            listener.onCommand(command, memory.state(), tally);
            RecordHeaders headers = new RecordHeaders();
            headers.add(COMMAND_ID_HEADER, command.commandId().getBytes(UTF_8));
            context().forward(new Record<>(robot, command.toLightringLeds(), command.stampMs(), headers));
        });
    }
}
