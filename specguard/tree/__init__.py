"""The goal-tree language: ``Goal`` and ``All``, ``Distance`` and ``Constraint``, result keys, the reward formula."""
