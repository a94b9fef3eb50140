"""The spec: a goal tree with its initial env, algorithm and budget, the algorithms we know, and spec files."""
