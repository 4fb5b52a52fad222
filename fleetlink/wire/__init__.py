"""The edge <-> uplink wire contract: batches of records, acknowledgements, key expressions.

Pure: bytes in, bytes out. Both sides import this one package, so the format has one definition.

Batch (edge -> uplink, one Zenoh payload; little-endian throughout)::

    "FLB" | version u8 (=5) | codec u8 (0 none, 1 zlib, 2 zstd) | body length u32 | body (compressed)
    body:  site str16 | edge_id str16 | stream str16 | origin u64 | first_seq u64
           | n_schemas u16 | { fingerprint 8 bytes | schema JSON str32, or u32 0xFFFFFFFF } * n_schemas
           | n_groups u32 | { first_seq u64 | group_len u32 | group } * n_groups
    group: count u32 | n_fingerprints u16 | { fingerprint 8 bytes } * n
           | { payload_len u32 | payload } * count          (seqs first_seq, first_seq + 1, ...)

A group is what the edge's spool stores and reads back as one frame (``fleetlink.wire.groups``),
so a batch is built from whole groups without touching a record; seqs increase across groups
and may jump between them.

Record payload (what the edge spool stores, so a batch is built without re-encoding)::

    flags u8 (bit 0: raw value, bit 1: null key, bit 2: source seq) | timestamp_ms i64 | value bytes32
    | [source_seq u64, with bit 2] | topic str16 | key bytes32 | n_headers u16
    | { name str16 | value bytes32 } * n_headers

With bit 2 the record has one more header, ``fleetlink.seq`` = the decimal source seq (the ROS
publication sequence number), after the others. It keeps the rest of the payload (the *tail*:
topic, key, headers) the same for every record of one robot and mapping, so the edge encodes it
once and the uplink parses it once per batch. The edge writes version 5 and the uplink reads
only that (another version is refused with "unsupported batch version N"; the edge keeps such a
batch in its spool).

``origin`` is 0 for an at-least-once stream. A non-zero origin asks for exactly-once delivery: it
names the spool the seqs come from (a random 64-bit id made with the spool), and the uplink
writes each record of (site, edge, stream, origin) once, whatever seq it has already written
(docs/exactly-once.md).

A value is Avro single-object encoded (``C3 01`` + 8-byte CRC-64-AVRO fingerprint, little-endian,
+ Avro body) unless the raw flag is set (dead letters are produced exactly as given). A batch
lists every fingerprint its records use, with the schema JSON, so that any stateless uplink can
register it, until an uplink has acknowledged a batch carrying that schema: from then on the
edge sends the fingerprint alone (length 0xFFFFFFFF). An uplink remembers the schema
text of every batch it read; one that meets a left-out schema it does not know (restarted, or
another uplink) produces nothing of the batch and answers ``need_schemas`` with the missing
fingerprints, and the edge sends the batch again with their text. A schema costs 300-700 bytes
compressed, which outweighs a batch of a few small records (docs/wan_bytes.md).

Ack (uplink -> edge, uncompressed)::

    "FLA" | version u8 | edge_id str16 | stream str16 | first_seq u64 | last_seq u64 | status u8
    (0 ok, 1 error, 2 need_schemas, 3 held_back) | detail str16 | n_failures u32
    | { seq u64 | dead_lettered u8 | reason str16 } * n_failures
    | [n_missing u16 | { fingerprint 8 bytes } * n_missing, with status 2] | max_record_bytes u32

``ok``: every record of the batch is in Kafka, or in the dead-letter topic (listed in failures,
all with ``dead_lettered``); the edge may drop the whole range from its spool. ``error``: the
batch was not (entirely) made safe; the edge sends it again later. ``need_schemas``: nothing
was produced; send the batch again with the text of the listed schemas. ``held_back``: nothing
was produced, because an earlier batch of the stream was not (answered ``error`` or
``need_schemas``): send it again after that one, so that records keep their order (an edge that
does not know this status retries the batch as after an error). ``max_record_bytes``
is the largest Kafka record the uplink produces (0: not said): the edge learns it from every
answer and keeps larger records off the WAN (``fleetlink.wire.limits``).

Decoding anything malformed raises ``WireError`` with the reason and the offset.
"""

from fleetlink.wire.ack import ACK_MAGIC, Ack, AckStatus, RecordFailure, decode_ack, encode_ack
from fleetlink.wire.batch import (
    BATCH_MAGIC,
    BATCH_VERSION,
    MAX_BATCH_BYTES,
    Batch,
    BatchBody,
    Codec,
    decode_batch,
    decode_batch_head,
    encode_batch,
    encode_batch_groups,
    encode_batch_payloads,
    zstd_available,
)
from fleetlink.wire.errors import WireError
from fleetlink.wire.framing import VERSION
from fleetlink.wire.keys import (
    ROOT,
    ack_key,
    admin_key,
    check_key_chunk,
    check_key_name,
    command_key,
    events_key,
    ingest_key,
    site_prefix,
    via_key,
)
from fleetlink.wire.records import (
    FLAG_SOURCE_SEQ,
    SINGLE_OBJECT_MAGIC,
    SOURCE_SEQ_HEADER,
    VALUE_OFFSET,
    PayloadTemplate,
    Record,
    decode_payload,
    encode_payload,
    payload_fingerprint,
    payload_fingerprints,
    single_object,
    split_single_object,
)

__all__ = [
    "ACK_MAGIC",
    "BATCH_MAGIC",
    "BATCH_VERSION",
    "FLAG_SOURCE_SEQ",
    "MAX_BATCH_BYTES",
    "ROOT",
    "SINGLE_OBJECT_MAGIC",
    "SOURCE_SEQ_HEADER",
    "VALUE_OFFSET",
    "VERSION",
    "Ack",
    "AckStatus",
    "Batch",
    "BatchBody",
    "Codec",
    "PayloadTemplate",
    "Record",
    "RecordFailure",
    "WireError",
    "ack_key",
    "admin_key",
    "check_key_chunk",
    "check_key_name",
    "command_key",
    "decode_ack",
    "decode_batch",
    "decode_batch_head",
    "decode_payload",
    "encode_ack",
    "encode_batch",
    "encode_batch_groups",
    "encode_batch_payloads",
    "encode_payload",
    "events_key",
    "ingest_key",
    "payload_fingerprint",
    "payload_fingerprints",
    "single_object",
    "site_prefix",
    "split_single_object",
    "via_key",
    "zstd_available",
]
