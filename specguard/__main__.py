"""``python -m specguard``: the command line (see :mod:`specguard.cli`)."""

import sys

from specguard.cli import main

sys.exit(main())
