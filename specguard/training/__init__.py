"""Training one seed of a spec: the learning loop, its envs stepped together, auto weights, progress events and
its result."""
