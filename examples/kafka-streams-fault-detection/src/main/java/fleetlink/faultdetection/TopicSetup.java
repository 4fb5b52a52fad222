package fleetlink.faultdetection;

import java.util.ArrayList;
import java.util.HashMap;
import java.util.List;
import java.util.Map;
import java.util.Optional;
import java.util.OptionalInt;
import java.util.concurrent.ExecutionException;
import java.util.concurrent.TimeUnit;
import java.util.concurrent.TimeoutException;
import org.apache.kafka.clients.admin.Admin;
import org.apache.kafka.clients.admin.AdminClientConfig;
import org.apache.kafka.clients.admin.NewTopic;
import org.apache.kafka.clients.admin.TopicDescription;
import org.apache.kafka.common.KafkaFuture;
import org.apache.kafka.common.errors.TopicExistsException;
import org.apache.kafka.common.errors.UnknownTopicOrPartitionException;

/**
 * Before the topology starts: refuse sensor topics with different partition counts, and create
 * the topics that do not exist yet (Kafka Streams does not create its source topics). Missing
 * sensor topics get the existing ones' partition count; otherwise the broker's defaults.
 */
public final class TopicSetup {
    private static final long TIMEOUT_S = 30;

    private TopicSetup() {}

    public static void ensure(String bootstrap, Topics topics) throws StartupException {
        Map<String, Object> conf = Map.of(AdminClientConfig.BOOTSTRAP_SERVERS_CONFIG, bootstrap);
        try (Admin admin = Admin.create(conf)) {
            Map<String, Integer> existing = partitions(admin, topics.sensors());
            OptionalInt count = Copartitioning.check(existing);
            List<NewTopic> missing = new ArrayList<>();
            for (String name : topics.sensors()) {
                if (!existing.containsKey(name)) {
                    missing.add(newTopic(name, count));
                }
            }
            if (partitions(admin, List.of(topics.commands())).isEmpty()) {
                missing.add(newTopic(topics.commands(), OptionalInt.empty()));
            }
            create(admin, missing);
        } catch (InterruptedException e) {
            Thread.currentThread().interrupt();
            throw new StartupException("interrupted while checking the topics");
        }
    }

    private static NewTopic newTopic(String name, OptionalInt partitions) {
        Optional<Integer> count = partitions.isPresent() ? Optional.of(partitions.getAsInt()) : Optional.empty();
        return new NewTopic(name, count, Optional.empty());
    }

    private static Map<String, Integer> partitions(Admin admin, List<String> names)
            throws StartupException, InterruptedException {
        Map<String, Integer> out = new HashMap<>();
        Map<String, KafkaFuture<TopicDescription>> futures = admin.describeTopics(names).topicNameValues();
        for (Map.Entry<String, KafkaFuture<TopicDescription>> entry : futures.entrySet()) {
            try {
                out.put(entry.getKey(), entry.getValue().get(TIMEOUT_S, TimeUnit.SECONDS).partitions().size());
            } catch (ExecutionException e) {
                if (!(e.getCause() instanceof UnknownTopicOrPartitionException)) {
                    throw new StartupException("cannot describe topic " + entry.getKey() + ": " + e.getCause(), e.getCause());
                }
            } catch (TimeoutException e) {
                throw new StartupException("Kafka did not answer within " + TIMEOUT_S + " s (is it up?)", e);
            }
        }
        return out;
    }

    private static void create(Admin admin, List<NewTopic> topics) throws StartupException, InterruptedException {
        if (topics.isEmpty()) {
            return;
        }
        for (Map.Entry<String, KafkaFuture<Void>> entry : admin.createTopics(topics).values().entrySet()) {
            try {
                entry.getValue().get(TIMEOUT_S, TimeUnit.SECONDS);
            } catch (ExecutionException e) {
                if (!(e.getCause() instanceof TopicExistsException)) { // created meanwhile by someone else: fine
                    throw new StartupException("cannot create topic " + entry.getKey() + ": " + e.getCause(), e.getCause());
                }
            } catch (TimeoutException e) {
                throw new StartupException("Kafka did not create " + entry.getKey() + " within " + TIMEOUT_S + " s", e);
            }
        }
    }
}
