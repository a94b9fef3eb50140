"""Agents trained elsewhere: loaded from a saved model, an rl-zoo3 or Hub folder, a model in memory or a callable,
as one policy the rest of specguard runs (:mod:`~specguard.agents.sources`, :mod:`~specguard.agents.agent`)."""
