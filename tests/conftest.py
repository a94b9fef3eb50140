import atexit
import os
import shutil
import sys
import tempfile

import pytest
import torch  # noqa: F401
from hypothesis import HealthCheck, settings

# torch is imported before any test runs: pytester takes sys.modules back to what it was before a test that uses it,
# dropping what the test imported, and torch imported a second time into one process dies in a segmentation fault
# (tests/test_doors.py's three runs of one test in a process crashed pytest so).

pytest_plugins = ["pytester"]

# stable-baselines3 makes an empty folder /tmp/SB3-<time> for each quiet model that learns without a logger of its own
# (the tests that train SB3 directly): here they share one folder per process, removed when the process ends.
_SB3_LOGDIR = tempfile.mkdtemp(prefix="specguard-tests-sb3-")
os.environ.setdefault("SB3_LOGDIR", _SB3_LOGDIR)
atexit.register(shutil.rmtree, _SB3_LOGDIR, ignore_errors=True)

# Headless rendering for check_env's render-mode checks.
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

settings.register_profile(
    "ci", max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
settings.register_profile("dev", max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") else "dev"))


@pytest.fixture
def build_counts(monkeypatch):
    """Counts, from here on, the goal trees compiled (``compile_tree``, wherever imported) and code-generated."""
    from specguard.construction import compiled as compiled_module

    counts = {"compile": 0, "codegen": 0}
    compile_tree, source_of = compiled_module.compile_tree, compiled_module.source_of

    def counting_compile(*args, **kwargs):
        counts["compile"] += 1
        return compile_tree(*args, **kwargs)

    def counting_source(*args, **kwargs):
        counts["codegen"] += 1
        return source_of(*args, **kwargs)

    for name, module in list(sys.modules.items()):
        if name.startswith("specguard") and getattr(module, "compile_tree", None) is compile_tree:
            monkeypatch.setattr(module, "compile_tree", counting_compile)
    monkeypatch.setattr(compiled_module, "source_of", counting_source)
    return counts
