"""Record buffers between the edge pipeline and the WAN sender.

- ``Spool``: durable, on local disk, for ``at_least_once`` mappings (docs/spool.md).
- ``MemoryBuffer``: bounded, in RAM, for ``best_effort`` mappings.

Both implement ``RecordBuffer`` (see ``edge.spool.api`` for the sender's loop).
"""

from fleetlink.edge.spool.api import (
    FSYNC_POLICIES,
    FULL_POLICIES,
    FsyncPolicy,
    FullPolicy,
    RecordBuffer,
    SpoolBatch,
    SpoolGroup,
    SpoolOptions,
    SpoolRecord,
    SpoolStats,
)
from fleetlink.edge.spool.memory import MemoryBuffer
from fleetlink.edge.spool.spool import Spool

__all__ = [
    "FSYNC_POLICIES",
    "FULL_POLICIES",
    "FsyncPolicy",
    "FullPolicy",
    "MemoryBuffer",
    "RecordBuffer",
    "Spool",
    "SpoolBatch",
    "SpoolGroup",
    "SpoolOptions",
    "SpoolRecord",
    "SpoolStats",
]
