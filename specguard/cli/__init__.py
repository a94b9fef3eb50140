"""The ``specguard`` command line: ``show``, ``run`` and ``reproduce``."""
