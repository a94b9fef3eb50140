"""Training one seed of a spec: the learning loop, auto weights, progress events, its result, and rollouts."""
