"""The operators' shared text; the per-child weights rule they share is specguard.extend's (tests/test_extend.py)."""

from __future__ import annotations

from specguard_plugins._checks import weights_text


def test_weights_text_is_exact():
    assert weights_text(None) == ""
    assert weights_text((0.1 + 0.2, 1.0, 2.5)) == " weights=(0.30000000000000004, 1, 2.5)"
