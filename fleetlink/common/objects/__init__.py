"""An S3-compatible object store: where the edge puts the large payloads of claim-checked records.

``sigv4`` signs requests (AWS Signature Version 4, pure), ``store.ObjectStore`` puts, gets and
heads objects over ``httpx`` (a dependency already), ``config.ObjectStoreSection`` is the
``objects:`` section of a config. A small client of the three calls fleetlink makes rather than
boto3: boto3 with botocore installs some 100 MB, more than half an edge's whole install
(docs/images.md, "The object store").
"""

from fleetlink.common.objects.config import ObjectStoreSection
from fleetlink.common.objects.errors import ObjectStoreError
from fleetlink.common.objects.store import ObjectInfo, ObjectStore

__all__ = ["ObjectInfo", "ObjectStore", "ObjectStoreError", "ObjectStoreSection"]
