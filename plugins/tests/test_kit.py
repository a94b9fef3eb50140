"""specguard's operator contract kit (docs/semantics.md, "The operator contract") run on the plugin's classes."""

from __future__ import annotations

from specguard_plugins import AnyOf, Avoid, Sequence

from specguard.testing import parametrize_with_checks


@parametrize_with_checks([AnyOf, Sequence, Avoid])
def test_contract(operator, check):
    check(operator)
