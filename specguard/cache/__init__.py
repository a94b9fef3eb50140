"""Run identity and the run cache: canonical forms, the probe, library versions, the fingerprint, stored models."""
