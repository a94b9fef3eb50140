"""The constructed environment: the initial env, Algorithm 1 (reference), its compiled form and code, checks, ``SpecEnv``."""
