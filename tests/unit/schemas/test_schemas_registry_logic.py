"""Registry client logic against in-memory stand-ins (no sockets): caching, refusals, messages."""

from __future__ import annotations

import errno
import json
from dataclasses import dataclass, field
from typing import Any

import httpx
import pytest
from confluent_kafka.schema_registry import Schema
from confluent_kafka.schema_registry.error import SchemaRegistryError

from fleetlink.schemas.errors import IncompatibleSchemaError, RegistryError
from fleetlink.schemas.registry import RegistryUnavailableError, SchemaRegistry, subject_for_topic

V1: dict[str, Any] = {
    "type": "record",
    "name": "T",
    "namespace": "ros.t",
    "fields": [{"name": "a", "type": "int"}],
}
V2: dict[str, Any] = {**V1, "fields": [*V1["fields"], {"name": "b", "type": "string"}]}
REFUSAL = (
    "Incompatible artifact: t-value [AVRO], num of incompatible diffs: {1}, "
    "list of diff types: [b at /fields/1]"
)


@dataclass
class _Version:
    version: int


@dataclass
class FakeClient:
    """The few SchemaRegistryClient calls the adapter makes, with a scripted registry behind them."""

    refuse: set[str] = field(default_factory=set)  # schema texts the registry refuses (409)
    status: int = 0  # when set, every call fails with this HTTP status
    registered: dict[str, int] = field(default_factory=dict)
    calls: list[str] = field(default_factory=list)
    broken: list[Exception] = field(default_factory=list)  # raised by the next calls, one each

    def register_schema(self, subject: str, schema: Schema) -> int:
        self.calls.append("register")
        if self.broken:
            raise self.broken.pop(0)
        if self.status:
            raise SchemaRegistryError(self.status, self.status * 100, "boom")
        if schema.schema_str in self.refuse:
            raise SchemaRegistryError(409, 409, REFUSAL)
        return self.registered.setdefault(schema.schema_str or "", len(self.registered) + 1)

    def get_schema(self, schema_id: int) -> Schema:
        self.calls.append("get_schema")
        if self.broken:
            raise self.broken.pop(0)
        for text, known in self.registered.items():
            if known == schema_id:
                return Schema(text, "AVRO")
        raise SchemaRegistryError(404, 40403, "Schema not found")

    def get_latest_version(self, subject: str) -> _Version:
        return _Version(len(self.registered))

    def set_compatibility(self, subject: str, level: str) -> None:
        self.calls.append(f"compat {subject} {level}")

    def __exit__(self, *args: object) -> None:
        return None


def _registry(client: FakeClient, answer: httpx.Response) -> SchemaRegistry:
    reg = SchemaRegistry("http://registry.invalid/apis/ccompat/v7")
    reg._client = client
    reg._http = httpx.Client(base_url=reg.url, transport=httpx.MockTransport(lambda request: answer))
    return reg


def test_topic_name_strategy() -> None:
    assert subject_for_topic("fleet.imu") == "fleet.imu-value"


def test_register_is_cached_per_subject_and_schema() -> None:
    client = FakeClient()
    reg = _registry(client, httpx.Response(200, json={"is_compatible": True}))
    first = reg.register("t-value", V1)
    assert reg.register("t-value", V1) == first
    assert client.calls == ["register"]
    assert reg.register("u-value", V1) == first  # another subject asks the registry again
    assert client.calls == ["register", "register"]
    assert reg.schema_by_id(first) == V1
    assert client.calls == ["register", "register"]  # known from the registration


def test_refused_registration_carries_subject_version_and_message() -> None:
    client = FakeClient(refuse={json.dumps(V2)})
    reg = _registry(client, httpx.Response(200, json={"is_compatible": False}))
    reg.register("t-value", V1)
    with pytest.raises(IncompatibleSchemaError) as info:
        reg.register("t-value", V2)
    assert (info.value.subject, info.value.version, info.value.registry_message) == ("t-value", 1, REFUSAL)


@pytest.mark.parametrize(
    ("answer", "message"),
    [
        # Confluent-style verbose answer: the reasons are in the answer
        (
            httpx.Response(200, json={"is_compatible": False, "messages": ["b has no default"]}),
            "b has no default",
        ),
        # Apicurio answers without reasons: they come from the refused registration
        (httpx.Response(200, json={"is_compatible": False}), REFUSAL),
    ],
)
def test_check_compatible_reports_the_registry_message(answer: httpx.Response, message: str) -> None:
    client = FakeClient(refuse={json.dumps(V2)})
    reg = _registry(client, answer)
    reg.register("t-value", V1)
    with pytest.raises(IncompatibleSchemaError) as info:
        reg.check_compatible("t-value", V2)
    assert info.value.registry_message == message
    assert info.value.version == 1
    assert list(client.registered) == [json.dumps(V1)]  # nothing new registered


@pytest.mark.parametrize(
    "answer",
    [httpx.Response(200, json={"is_compatible": True}), httpx.Response(404, json={"error_code": 40401})],
)
def test_compatible_or_new_subject_passes(answer: httpx.Response) -> None:
    reg = _registry(FakeClient(), answer)
    reg.check_compatible("t-value", V2)


@pytest.mark.parametrize(
    ("status", "error"),
    [(500, RegistryUnavailableError), (503, RegistryUnavailableError), (422, RegistryError)],
)
def test_failures_are_classified(status: int, error: type[RegistryError]) -> None:
    reg = _registry(FakeClient(status=status), httpx.Response(status, text="nope"))
    with pytest.raises(error) as registering:
        reg.register("t-value", V1)
    assert registering.value.subject == "t-value"
    assert isinstance(registering.value, RegistryUnavailableError) == (status >= 500)
    with pytest.raises(error):
        reg.check_compatible("t-value", V1)


def test_unknown_id() -> None:
    reg = _registry(FakeClient(), httpx.Response(200, json={}))
    with pytest.raises(RegistryError, match="40403"):
        reg.schema_by_id(99)


def test_set_compatibility_is_passed_through() -> None:
    client = FakeClient()
    _registry(client, httpx.Response(200, json={})).set_compatibility("t-value", "BACKWARD")
    assert client.calls == ["compat t-value BACKWARD"]


def _bad_fd() -> OSError:
    return OSError(errno.EBADF, "Bad file descriptor")


def test_a_connection_that_died_under_a_call_is_replaced() -> None:
    """A kept-alive connection the pool reused died under the request: the call is made again."""
    client = FakeClient(broken=[_bad_fd(), httpx.RemoteProtocolError("Server disconnected")])
    reg = _registry(client, httpx.Response(200, json={}))
    assert reg.register("t-value", V1) == 1
    assert client.calls == ["register"] * 3
    client.broken = [httpx.ReadError("connection reset")]
    reg._schemas.clear()
    assert reg.schema_by_id(1) == V1
    assert client.calls[3:] == ["get_schema"] * 2


def test_connections_that_keep_dying_make_the_registry_unavailable() -> None:
    client = FakeClient(broken=[_bad_fd() for _ in range(3)])
    reg = _registry(client, httpx.Response(200, json={}))
    with pytest.raises(RegistryUnavailableError, match="Bad file descriptor"):
        reg.register("t-value", V1)
    assert client.calls == ["register"] * 3


@pytest.mark.parametrize("timeout", [httpx.ReadTimeout("read timed out"), TimeoutError("timed out")])
def test_a_timeout_is_not_tried_again(timeout: Exception) -> None:
    """Waiting the whole timeout again, twice, would only delay the caller's own retry."""
    client = FakeClient(broken=[timeout])
    reg = _registry(client, httpx.Response(200, json={}))
    with pytest.raises(RegistryUnavailableError):
        reg.register("t-value", V1)
    assert client.calls == ["register"]


def test_the_compatibility_check_replaces_a_dead_connection() -> None:
    failures = [httpx.ReadError("Bad file descriptor")]
    sent: list[str] = []

    def answer(request: httpx.Request) -> httpx.Response:
        sent.append(request.url.path)
        if failures:
            raise failures.pop(0)
        return httpx.Response(200, json={"is_compatible": True})

    reg = _registry(FakeClient(), httpx.Response(200))
    reg._http = httpx.Client(base_url=reg.url, transport=httpx.MockTransport(answer))
    reg.check_compatible("t-value", V1)
    assert len(sent) == 2
