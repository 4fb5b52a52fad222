"""ROS 2 services on the rmw_zenoh wire: a server and a client (rmw_zenoh.md §5, §12).

A service is a Zenoh queryable on the data key ``<domain>/<service>/<dds type>/<hash>`` (the
type without ``Request_``/``Response_``, the hash of the *service* type), announced by an
``SS`` liveliness token; a client announces itself with an ``SC`` token and sends each request
as a query on that key: CDR request as payload, attachment ``(sequence number, send time,
client GID)``, target ALL_COMPLETE, no consolidation. The server answers with one reply on the
same key whose attachment echoes the request's sequence number and the *client's* GID.

* :class:`RosServiceServer` serves a handler; the handler gets a :class:`ServiceCall` and
  answers it at once (return the response CDR) or later from any thread (``call.reply``), as an
  action server does for ``get_result``.
* :class:`RosServiceClient` calls: :meth:`RosServiceClient.call_cdr` returns the response CDR
  or raises :class:`ServiceTimeoutError` (no answer in time), :class:`ServiceUnavailableError`
  (no server announced) or :class:`ServiceGoneError` (the server went away during the call: the
  request may or may not have been handled).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import zenoh

from fleetlink.common.lifecycle import StartStop
from fleetlink.roswire.attachment import Attachment, encode
from fleetlink.roswire.attachment import decode as decode_attachment
from fleetlink.roswire.errors import AttachmentError, RoswireError
from fleetlink.roswire.gid import entity_gid
from fleetlink.roswire.names import data_key
from fleetlink.roswire.qos import SERVICES, QoS
from fleetlink.roswire.session import undeclare
from fleetlink.roswire.tokens import EntityKind

if TYPE_CHECKING:
    from fleetlink.roswire.node import RosNode

log = logging.getLogger(__name__)


class ServiceError(RoswireError):
    """A service call that did not return a response."""

    def __init__(self, service: str, reason: str) -> None:
        super().__init__(f"service {service}: {reason}")
        self.service = service
        self.reason = reason


class ServiceTimeoutError(ServiceError):
    """No response within the timeout."""


class ServiceUnavailableError(ServiceError):
    """No server for the service (no ``SS`` token): the request was not sent."""


class ServiceGoneError(ServiceError):
    """The query ended without a reply before the timeout: the server went away during the call."""


class ServiceCall:
    """One request a server received; answer it exactly once with :meth:`reply` or :meth:`fail`."""

    def __init__(self, server: RosServiceServer, query: zenoh.Query, payload: bytes, attachment: Attachment):
        self.payload = payload
        self.attachment = attachment
        self._server = server
        self._query: zenoh.Query | None = query
        self._lock = threading.Lock()

    @property
    def answered(self) -> bool:
        """Whether the call has been replied to (or failed) already."""
        return self._query is None

    def reply(self, response_cdr: bytes) -> bool:
        """Send the response (False when the call was answered before or its query is gone)."""
        with self._lock:
            query, self._query = self._query, None
        if query is None:
            return False
        att = encode(self.attachment.seq, time.time_ns(), self.attachment.gid, self.attachment.version)
        try:
            query.reply(self._server.key, response_cdr, attachment=att)
            return True
        except zenoh.ZError as exc:
            log.debug("service %s: reply failed: %s", self._server.service, exc)
            return False
        finally:
            query.drop()

    def fail(self, reason: str) -> bool:
        """Answer with an error reply (rmw_zenoh clients drop it; fleetlink clients report it)."""
        with self._lock:
            query, self._query = self._query, None
        if query is None:
            return False
        try:
            query.reply_err(reason.encode())
            return True
        except zenoh.ZError:
            return False
        finally:
            query.drop()


ServiceHandler = Callable[[ServiceCall], bytes | None]
"""Returns the response CDR, or None when it will answer the call later."""


class RosServiceServer(StartStop):
    """Serves one ROS 2 service as rmw_zenoh does: a queryable on the data key and an ``SS`` token."""

    def __init__(
        self,
        node: RosNode,
        service: str,
        typename: str,
        handler: ServiceHandler,
        *,
        type_hash: str | None = None,
        qos: QoS = SERVICES,
    ) -> None:
        self.node = node
        self.service = node.resolve(service)
        self.typename = typename
        self.handler = handler
        self.qos = qos
        self._type_hash = type_hash
        self._queryable: Any = None
        self._token: zenoh.LivelinessToken | None = None
        self.key = ""
        self.token_key = ""
        self.requests = 0
        self.bad_requests = 0

    @property
    def type_hash(self) -> str:
        """The service type's hash as given, else computed once from the node's type store."""
        if self._type_hash is None:
            self._type_hash = self.node.type_hash(self.typename)
        return self._type_hash

    def start(self) -> RosServiceServer:
        """Declare the queryable and the ``SS`` token; returns self."""
        if self._queryable is not None:
            return self
        session = self.node.session
        self.key = data_key(self.node.domain_id, self.service, self.typename, self.type_hash)
        self._queryable = session.declare_queryable(self.key, self._on_query, complete=True)
        self.token_key = self.node.endpoint_token(
            EntityKind.SERVICE_SERVER, self.service, self.typename, type_hash=self.type_hash, qos=self.qos
        )
        self._token = session.liveliness().declare_token(self.token_key)
        self.node.adopt(self)
        return self

    def stop(self) -> None:
        """Undeclare the token and the queryable, and detach from the node."""
        if self._token is not None:
            undeclare(self._token, log, "token", self.service)
            self._token = None
        if self._queryable is not None:
            undeclare(self._queryable, log, "queryable", self.service)
            self._queryable = None
        self.node.forget(self)

    def _on_query(self, query: zenoh.Query) -> None:
        raw = query.attachment
        try:
            if raw is None:
                raise AttachmentError(b"", "the request carries no attachment")
            attachment = decode_attachment(raw.to_bytes())
        except AttachmentError as exc:  # rmw_zenoh drops such requests; say why instead
            self.bad_requests += 1
            query.reply_err(f"bad request attachment: {exc}".encode())
            query.drop()
            return
        payload = query.payload
        call = ServiceCall(self, query, payload.to_bytes() if payload is not None else b"", attachment)
        self.requests += 1
        try:
            response = self.handler(call)
        except Exception as exc:  # noqa: BLE001 - a failing handler answers with an error, the server lives on
            log.warning("service %s: handler failed: %r", self.service, exc)
            call.fail(f"handler failed: {exc!r}")
            return
        if response is not None:
            call.reply(response)


class RosServiceClient(StartStop):
    """Calls one ROS 2 service as rmw_zenoh does: an ``SC`` token and one query per request."""

    def __init__(
        self,
        node: RosNode,
        service: str,
        typename: str,
        *,
        type_hash: str | None = None,
        qos: QoS = SERVICES,
    ) -> None:
        self.node = node
        self.service = node.resolve(service)
        self.typename = typename
        self.qos = qos
        self._type_hash = type_hash
        self._token: zenoh.LivelinessToken | None = None
        self._lock = threading.Lock()
        self.seq = 0
        self.key = ""
        self.token_key = ""
        self.gid = b""

    @property
    def type_hash(self) -> str:
        """The service type's hash as given, else computed once from the node's type store."""
        if self._type_hash is None:
            self._type_hash = self.node.type_hash(self.typename)
        return self._type_hash

    def start(self) -> RosServiceClient:
        """Declare the ``SC`` token (which also fixes the client's GID); returns self."""
        if self._token is not None:
            return self
        self.key = data_key(self.node.domain_id, self.service, self.typename, self.type_hash)
        self.token_key = self.node.endpoint_token(
            EntityKind.SERVICE_CLIENT, self.service, self.typename, type_hash=self.type_hash, qos=self.qos
        )
        self.gid = entity_gid(self.token_key)
        self._token = self.node.session.liveliness().declare_token(self.token_key)
        self.node.adopt(self)
        return self

    def stop(self) -> None:
        """Undeclare the token and detach from the node."""
        if self._token is not None:
            undeclare(self._token, log, "token", self.service)
            self._token = None
        self.node.forget(self)

    def server_available(self, timeout: float = 1.0) -> bool:
        """Whether an ``SS`` token for this service (any type) answers a liveliness query."""
        try:
            return self.node.announced(EntityKind.SERVICE_SERVER, self.service, timeout)
        except zenoh.ZError:
            return False

    def wait_for_server(
        self, timeout: float, *, poll: float = 0.1, stop: threading.Event | None = None
    ) -> bool:
        """Wait until a server is announced (at most ``timeout`` seconds)."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if self.server_available(min(max(left, 0.05), 1.0)):
                return True
            left = deadline - time.monotonic()
            if left <= 0 or (stop is not None and stop.is_set()):
                return False
            time.sleep(min(poll, left))

    def call_cdr(self, request_cdr: bytes, timeout: float) -> bytes:
        """Send one request; the response's CDR, or a :class:`ServiceError` saying why not."""
        if self._token is None:
            raise RoswireError(f"service client on {self.service} is not started")
        with self._lock:
            self.seq += 1
            seq = self.seq
        attachment = encode(seq, time.time_ns(), self.gid, self.node.attachment_version)
        started = time.monotonic()
        errors: list[str] = []
        try:
            replies = self.node.session.get(
                self.key,
                payload=request_cdr,
                attachment=attachment,
                target=zenoh.QueryTarget.ALL_COMPLETE,
                consolidation=zenoh.ConsolidationMode.NONE,
                timeout=max(timeout, 0.001),
            )
            for reply in replies:
                ok = reply.ok
                if ok is None:
                    err = reply.err
                    errors.append(err.payload.to_bytes()[:300].decode("utf-8", "replace") if err else "error")
                    continue
                raw = ok.attachment
                try:
                    answer = decode_attachment(raw.to_bytes()) if raw is not None else None
                except AttachmentError:
                    answer = None
                if answer is not None and answer.seq != seq:
                    continue  # not the answer to this request
                return ok.payload.to_bytes()
        except zenoh.ZError as exc:
            raise ServiceError(self.service, f"query failed: {exc}") from None
        elapsed = time.monotonic() - started
        real_errors = [e for e in errors if "timeout" not in e.lower()]
        if real_errors:
            raise ServiceError(self.service, f"the server answered with an error: {real_errors[0]}")
        if elapsed >= timeout * 0.98 or errors:
            raise ServiceTimeoutError(self.service, f"no response within {timeout:.3g} s")
        raise ServiceGoneError(
            self.service, f"the query ended after {elapsed:.3g} s without a response (no server answered)"
        )
