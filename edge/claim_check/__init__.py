"""Claim checks: a record's large payload goes to an object store, the record carries a reference.

Pure parts only: the mapping's ``claim_check`` spec, the reference schema a claim-checking
mapping writes, object keys and content types, the jobs handed to the uploader
(``edge.runtime.offloader``). See docs/images.md.
"""

from fleetlink.edge.claim_check.jobs import Claimed, ClaimJob, ObjectRef, Upload
from fleetlink.edge.claim_check.naming import content_type_for, object_key
from fleetlink.edge.claim_check.schema import OBJECT_REF_SCHEMA, ClaimCheckError, claim_schema, ref_field
from fleetlink.edge.claim_check.spec import ClaimCheckSpec

__all__ = [
    "OBJECT_REF_SCHEMA",
    "ClaimCheckError",
    "ClaimCheckSpec",
    "ClaimJob",
    "Claimed",
    "ObjectRef",
    "Upload",
    "claim_schema",
    "content_type_for",
    "object_key",
    "ref_field",
]
