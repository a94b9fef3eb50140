"""Falsifying trained agents: the guided search for failing starts over a start space, its verdict and its reports.

Everything here works on any policy callable, below ``spec/`` in the layering (start spaces themselves are
:mod:`specguard.starts`). The two modules outside it only connect it: :mod:`specguard.engine.falsify_run`
makes a spec's cached run such a policy (it needs the spec and its trained model), and
:mod:`specguard.pytest_plugin.falsify_item` is the ``[falsify]`` item's door.
"""
