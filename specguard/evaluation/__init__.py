"""Evaluating a policy on a spec's env: its episodes and their seeds, a model as a policy, and rollouts; below
training and agents trained elsewhere alike."""
