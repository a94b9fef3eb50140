"""The baseline gate: stored baselines, comparisons with them (extra seeds while open), and what a gate can see."""
