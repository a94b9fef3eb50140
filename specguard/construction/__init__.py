"""The constructed environment: the initial env, Algorithm 1 (reference), the compiled form, ``SpecEnv``."""
