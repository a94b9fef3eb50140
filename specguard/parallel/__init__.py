"""Tasks in parallel, each failing alone: a process per task (or a Dask cluster), reports over a pipe, clean stops.

Generic: it knows nothing of specs. The engine gives it one task per seed.
"""
