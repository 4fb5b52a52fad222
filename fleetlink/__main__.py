import sys

from fleetlink.cli import main

sys.exit(main())
