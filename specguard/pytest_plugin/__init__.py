"""The pytest plugin (``pytest --goal-specs``): hooks in ``plugin``, the logic in plain modules beside it."""
