"""``python -m fleetlink.cli``: the same as ``fleetlink``."""

import sys

from fleetlink.cli import main

sys.exit(main())
