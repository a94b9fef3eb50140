"""highway-fast-v0 (``highway.py``), opt-in: ``pytest --goal-specs example_specs -m highway``.

Needs the ``highway`` extra (``pip install -e ".[highway]"``); its training takes minutes per seed
(docs/guide/your-environment.md, "Example specs").
"""

from __future__ import annotations

import pytest

import specguard as sg

pytest.importorskip("highway_env", reason='needs the highway extra: pip install -e ".[highway]"')

from example_specs import highway  # after the skip: it imports highway_env

test_highway = sg.goal_specs(highway.specs, marks={key: pytest.mark.highway for key in highway.specs})
