"""Specs trained and judged: specs and budgets, training one seed, cache keys and the cache, ``run_spec``."""
