"""``python -m planner.cli``: the ``crosscert`` command without its script."""

import sys

from . import main

sys.exit(main())
