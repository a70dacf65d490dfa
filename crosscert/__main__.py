"""``python -m crosscert``: the ``crosscert`` command without its script."""

import sys

from crosscert.planner.cli import main

sys.exit(main())
