"""The four case studies of the source paper (SPEC.md section 5) as goal trees.

Each module defines ``initial_env``, ``trees`` (``{"a": ..., "b": ..., "c": ..., "w": ...}``
where the case has them) and ``ppo_kwargs`` (the paper's PPO settings).
"""
