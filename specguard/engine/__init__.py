"""Specs run and judged: ``run_spec``, the seeds of a run, the worker task, verdicts, ``SpecResult``, reproductions."""
