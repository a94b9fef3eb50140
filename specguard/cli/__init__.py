"""The ``specguard`` command line: ``show``, ``plan``, ``run``, ``reproduce`` and ``falsify``."""
