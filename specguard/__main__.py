"""``python -m specguard``: the command line (see :mod:`specguard.cli.main`)."""

import sys

from specguard.cli.main import main

sys.exit(main())
