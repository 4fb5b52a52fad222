"""``python -m fleetlink.examples.fault_detection``: run the fault-detection app until SIGINT/SIGTERM."""

import sys

from fleetlink.examples.fault_detection.cli import main

sys.exit(main())
