"""The four case studies of the source paper, and CartPole beyond it, as goal specs.

Their definitions are in docs/guide/case-studies.md, "Definitions".

Each case-study module reads as the paper's iterative environment design:
``initial_env``, the goals, then ``specs`` (``{"a": ..., "b": ..., "c": ...,
"w": ..., "baseline": ...}`` where the case has them), each refinement derived
from the previous one with a line on what it changes, what the paper observed
and what we measured; ``trees`` holds their goal trees and ``PAPER`` the
paper's reported figures. Every spec is declared once: ``pytest --goal-specs``
(``test_case_studies.py``), ``specguard run``/``show`` and ``specguard
reproduce`` all read ``specs``.
"""
