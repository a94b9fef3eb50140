"""The operator contract kit behind :mod:`specguard.testing`: the named checks, their examples, a replay env."""
