"""``python -m rce_gtsam.cli``: the ``rce`` command."""

import sys

from .app import main

sys.exit(main())
