"""The fingerprint: every change that can change a result changes the key, and nothing else does."""

from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys
import textwrap
import threading
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import specguard as sg
from example_specs import pendulum
from specguard.cache.canonical import canonical, digest
from specguard.cache.fingerprint import fingerprint_spec
from specguard.cache.probe import probe

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1}
BUDGET = sg.Budget(timesteps=128, min_seeds=1, eval_episodes=2)


def spec(tree=None, initial=None, **kwargs):
    kwargs.setdefault("budget", BUDGET)
    kwargs.setdefault("trainer", sg.SB3(hyperparameters=TINY))
    return sg.Spec(initial or pendulum.initial_env, tree or pendulum.trees["w"], **kwargs)


def shaped(fn, scale=2.0):
    return sg.All(sg.Goal("up", x=(0.9, 1.0)).annotate(sg.Distance(fn, scale=scale)), name="pendulum")


def functions(source, **namespace):
    """Functions defined by ``source`` in a fresh module namespace holding ``namespace``."""
    ns = {"np": np, "__name__": "user_module", **namespace}
    exec(textwrap.dedent(source), ns)
    return ns


# -- numbers --------------------------------------------------------------------------


def test_bounds_in_full_precision():
    # `:g` formatting once gave these two goals one key.
    a = sg.Goal("p", x=(0.9661231, 1.0))
    b = sg.Goal("p", x=(0.9661234, 1.0))
    assert digest(a) != digest(b)


@given(st.floats(allow_nan=False, allow_infinity=False, width=64), st.floats(allow_nan=False, allow_infinity=False))
def test_any_two_different_numbers_give_different_keys(x, y):
    assert (digest(x) == digest(y)) == (x == y and np.copysign(1, x) == np.copysign(1, y))


def goal_tree(lo, hi, weight, scale):
    return sg.All(
        sg.Goal("a", x=(lo, hi)).annotate(sg.Distance(pendulum.position_distance, scale=scale)),
        sg.Goal("b", omega=(-1, 1)),
        name="r",
        weights=(weight, 1.0),
    )


@given(
    st.integers(0, 3),
    st.floats(-10, 0, allow_nan=False),
    st.floats(0.01, 10, allow_nan=False),
)
def test_a_change_to_any_number_in_a_tree_changes_the_key(which, value, positive):
    base = [-0.5, 0.5, 0.8, 2.0]
    changed = list(base)
    changed[which] = value if which == 0 else positive
    if changed == base:
        return
    assert digest(goal_tree(*base)) != digest(goal_tree(*changed))


@given(
    st.sampled_from(["timesteps", "min_seeds", "max_seeds", "eval_episodes", "max_eval_episodes", "wall_clock_s"]),
    st.integers(2, 10_000),
)
def test_a_change_to_any_budget_field_changes_the_key(field, value):
    base = sg.Budget(
        timesteps=1, min_seeds=1, max_seeds=10_000, eval_episodes=1, max_eval_episodes=10_000, wall_clock_s=1
    )
    changed = dataclasses.replace(base, **{field: value})
    assert digest(base) != digest(changed) or getattr(base, field) == value


@given(st.dictionaries(st.sampled_from(["gamma", "n_steps", "ent_coef"]), st.floats(0, 1), min_size=1))
def test_a_change_to_any_hyperparameter_changes_the_key(extra):
    assert digest({"learning_rate": 1e-3}) != digest({"learning_rate": 1e-3, **extra})


def test_names_change_the_key():
    assert digest(sg.Goal("p", x=(0, 1))) != digest(sg.Goal("q", x=(0, 1)))
    assert digest(sg.Goal("p", x=(0, 1))) != digest(sg.Goal("p", y=(0, 1)))


def test_numpy_arrays_by_content_and_containers_regardless_of_order():
    assert digest(np.zeros(3)) == digest(np.zeros(3))
    assert digest(np.zeros(3)) != digest(np.zeros(3, dtype=np.float32))
    assert digest(np.zeros(3)) != digest(np.zeros((3, 1)))
    assert digest({"a": 1, "b": 2}) == digest({"b": 2, "a": 1})
    assert digest({"x", "y", "z"}) == digest({"z", "y", "x"})


# -- functions --------------------------------------------------------------------------


def test_a_module_level_constant_a_function_reads_is_part_of_the_key():
    ns = functions("def near(s):\n    return abs(s.x - TARGET)\n", TARGET=1.0)
    before = digest(ns["near"])
    ns["TARGET"] = 0.5
    assert digest(ns["near"]) != before


def test_helper_functions_are_followed_recursively():
    ns = functions(
        """
        def scale(v):
            return v * K

        def helper(v):
            return scale(v) + 1

        def near(s):
            return abs(helper(s.x))
        """,
        K=2.0,
    )
    before = digest(ns["near"])
    ns["K"] = 3.0  # two calls deep
    assert digest(ns["near"]) != before
    ns["K"] = 2.0
    assert digest(ns["near"]) == before
    exec("def scale(v):\n    return v * K * 1\n", ns)  # a changed helper body
    assert digest(ns["near"]) != before


def test_a_global_array_is_read_by_content():
    ns = functions("def near(s):\n    return float(TABLE[0])\n", TABLE=np.array([1.0, 2.0]))
    before = digest(ns["near"])
    ns["TABLE"][0] = 5.0  # mutated in place
    assert digest(ns["near"]) != before


def test_a_name_read_from_a_user_module_is_followed():
    import types

    helpers = types.ModuleType("my_helpers")
    helpers.OFFSET = 1.0
    ns = functions("def near(s):\n    return abs(s.x - my_helpers.OFFSET)\n", my_helpers=helpers)
    before = digest(ns["near"])
    helpers.OFFSET = 2.0
    assert digest(ns["near"]) != before


def test_recursive_functions_terminate():
    ns = functions("def f(n):\n    return 0 if n == 0 else f(n - 1)\n")
    assert digest(ns["f"]) == digest(ns["f"])


def test_formatting_comments_and_blank_lines_do_not_change_the_key():
    plain = functions("def near(s):\n    return abs(s.x - 1.0) * 2\n")
    styled = functions(
        """


        def near(s):
            # how far from the top


            return abs(
                s.x - 1.0   # centred
            ) * 2
        """
    )
    assert digest(plain["near"]) == digest(styled["near"])
    changed = functions("def near(s):\n    return abs(s.x - 1.0) * 3\n")
    assert digest(plain["near"]) != digest(changed["near"])


def test_captured_values_and_defaults_are_part_of_the_key():
    def make(target, power=1):
        def near(s, p=power):
            return abs(s.x - target) ** p

        return near

    assert digest(make(1.0)) == digest(make(1.0))
    assert digest(make(1.0)) != digest(make(0.5))
    assert digest(make(1.0)) != digest(make(1.0, power=2))


def factory_distance(inner):
    def distance(s):
        return inner(s)

    return distance


def test_a_function_captured_by_a_factory_has_no_address_in_its_key():
    key = digest(factory_distance(pendulum.position_distance))
    encoded = json.dumps(canonical(factory_distance(pendulum.position_distance)))
    assert " at 0x" not in encoded and not re.search(r"0x[0-9a-f]{8,}[^.0-9a-f]", encoded)
    assert key == digest(factory_distance(pendulum.position_distance))


def test_an_object_that_cannot_be_fingerprinted_is_an_error_naming_it():
    lock = threading.Lock()

    def near(s):
        with lock:
            return abs(s.x)

    with pytest.raises(sg.error.FingerprintError, match=r"closure 'lock'.*cannot fingerprint _thread.lock exactly"):
        fingerprint_spec(spec(shaped(near)))


def test_library_code_by_version_not_by_content():
    encoded = json.dumps(canonical(np.hypot)) + json.dumps(canonical(np.linalg.norm))
    assert "numpy" in encoded and not re.search(r"0x[0-9a-f]{8,}", encoded)


# -- specs ------------------------------------------------------------------------------


def test_every_spec_field_is_in_the_spec_key_and_only_run_fields_in_the_run_key():
    base = spec(expect={"pendulum": 0.5}, budget=sg.Budget(timesteps=128, min_seeds=1, max_seeds=3))
    fp = fingerprint_spec(base)
    counting = {
        "quorum": dataclasses.replace(base, quorum=2),
        "undecided": dataclasses.replace(base, undecided="pass"),
        "min_seeds": dataclasses.replace(base, budget=dataclasses.replace(base.budget, min_seeds=2)),
        "max_seeds": dataclasses.replace(base, budget=dataclasses.replace(base.budget, max_seeds=4)),
        "name": dataclasses.replace(base, name="other"),
    }
    for field, changed in counting.items():
        other = fingerprint_spec(changed)
        assert other.spec_key != fp.spec_key, field
        assert other.run_key(0) == fp.run_key(0), field  # one run does not depend on how runs are counted
    deciding = {
        "algorithm": dataclasses.replace(base, trainer=sg.SB3("A2C")),
        "hyperparameters": dataclasses.replace(base, trainer=sg.SB3(hyperparameters={**TINY, "gamma": 0.9})),
        "n_envs": dataclasses.replace(base, trainer=sg.SB3(hyperparameters=TINY, n_envs=2)),
        "normalize": dataclasses.replace(base, trainer=sg.SB3(hyperparameters=TINY, normalize=True)),
        "deterministic": dataclasses.replace(base, deterministic=False),
        "confidence": dataclasses.replace(base, confidence=0.9),
        "baseline": dataclasses.replace(base, baseline=True),
        "observation": dataclasses.replace(base, observation="features+env", trainer=sg.SB3(hyperparameters=TINY)),
        "expect": dataclasses.replace(base, expect={"pendulum": 0.6}),
        "timesteps": dataclasses.replace(base, budget=dataclasses.replace(base.budget, timesteps=129)),
        "tree": dataclasses.replace(base, tree=pendulum.trees["c"], expect={}),
        "initial_env": dataclasses.replace(base, initial_env=sg.InitialEnv("Pendulum-v1", ("x", "y", "omega"), g=9.0)),
    }
    for field, changed in deciding.items():
        other = fingerprint_spec(changed)
        assert other.spec_key != fp.spec_key and other.run_key(0) != fp.run_key(0), field
    assert fp.run_key(0) != fp.run_key(1)


def test_a_start_space_changes_neither_key_it_is_only_where_the_falsifier_searches():
    base = spec(expect={"pendulum": 0.5})
    searched = dataclasses.replace(base, starts={"theta": (-1.0, 1.0)})
    assert searched.starts == sg.StartSpace({"theta": (-1.0, 1.0)})  # ranges read as a StartSpace
    assert fingerprint_spec(searched).spec_key == fingerprint_spec(base).spec_key
    assert fingerprint_spec(searched).run_key(0) == fingerprint_spec(base).run_key(0)
    with pytest.raises(sg.error.InvalidSpec, match=r"Spec 'pendulum'.starts: expected starts to be a StartSpace"):
        dataclasses.replace(base, starts=[("theta", -1.0, 1.0)])


class Dynamics(gym.Wrapper):
    """An env whose behaviour the static part cannot see: it is made from a string id."""

    gain = 1.0

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward * self.gain, terminated, truncated, info


def test_the_two_probes_of_a_spec_compile_its_tree_once(build_counts):
    fingerprint_spec(spec(tree=sg.All(sg.Goal("up", x=(0.9, 1.0)), name="once")))
    assert build_counts == {"compile": 1, "codegen": 1}


def test_the_probe_sees_a_changed_env_that_the_static_part_cannot():
    gym.register("SpecguardProbe-v0", entry_point=lambda: Dynamics(gym.make("Pendulum-v1")))
    try:
        initial = sg.InitialEnv("SpecguardProbe-v0", features=("x", "y", "omega"))
        s = spec(initial=initial, baseline=True)
        before = probe(s)
        Dynamics.gain = 2.0  # a changed reward helper in a library the spec names only by id
        assert probe(s) != before
    finally:
        Dynamics.gain = 1.0
        del gym.registry["SpecguardProbe-v0"]


class Unseeded(gym.Wrapper):
    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=int(np.random.default_rng().integers(1 << 30)), options=options)
        return obs, info


def test_an_env_that_does_not_repeat_a_seeded_rollout_is_not_cacheable():
    initial = sg.InitialEnv(lambda: Unseeded(gym.make("Pendulum-v1")), features=("x", "y", "omega"))
    with pytest.warns(UserWarning, match="does not repeat a fixed-seed rollout"):
        fp = fingerprint_spec(spec(initial=initial))
    assert not fp.reproducible


def test_the_probe_records_an_env_that_raises_instead_of_raising():
    def broken():
        raise RuntimeError("no env today")

    s = spec(initial=sg.InitialEnv(broken, features=("x", "y", "omega")))
    assert probe(s) == probe(s)


@pytest.mark.slow
def test_the_key_is_the_same_across_processes_and_hash_seeds(tmp_path):
    script = textwrap.dedent(
        """
        import specguard as sg
        from example_specs import pendulum
        from specguard.cache.fingerprint import fingerprint_spec

        def factory(inner, target, names):
            def distance(s):
                return inner(s) + abs(s.omega - target) * len(names)
            return distance

        tree = sg.All(
            sg.Goal("up", x=(0.9661231, 1.0)).annotate(
                sg.Distance(factory(pendulum.position_distance, 0.25, frozenset("abcdef")), scale=3)
            ),
            sg.Goal("slow", omega=(-0.25, 0.25)),
            name="pendulum",
        )
        trainer = sg.SB3(hyperparameters={"n_steps": 64})
        spec = sg.Spec(pendulum.initial_env, tree, budget=sg.Budget(128), trainer=trainer)
        fp = fingerprint_spec(spec)
        print(fp.spec_key, fp.run_key(3))
        """
    )
    path = tmp_path / "key.py"
    path.write_text(script)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    keys = set()
    for hash_seed in ("1", "2", "random"):
        env = {**os.environ, "PYTHONHASHSEED": hash_seed, "PYTHONPATH": root}
        out = subprocess.run([sys.executable, str(path)], env=env, capture_output=True, text=True, check=True)
        keys.add(out.stdout.strip())
    assert len(keys) == 1


def test_fingerprints_are_computed_once_per_spec_object():
    s = spec()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert fingerprint_spec(s) is fingerprint_spec(s)


def test_a_user_operator_dataclass_is_keyed_by_its_description_and_its_code():
    from example_specs.at_least import AtLeast

    def tree(k):
        return AtLeast(k, sg.Goal("p", x=(0, 1)), sg.Goal("q", y=(0, 1)), name="r")

    keys = {digest(tree(1)), digest(tree(2))}
    assert len(keys) == 2  # its fields (and description) differ
    assert digest(tree(1)) == digest(tree(1))
    encoded = json.dumps(canonical(tree(2)))
    assert "AtLeast 'r' k=2" in encoded  # through the protocol: describe()

    class Changed(AtLeast):
        def contains(self, ctx):  # type: ignore[no-untyped-def]
            return sum(ctx.inside) > self.k

    changed = Changed(1, sg.Goal("p", x=(0, 1)), sg.Goal("q", y=(0, 1)), name="r")
    assert digest(changed) != digest(tree(1))  # same description, other code


def test_anytime_checkpoints_and_thresholds_are_part_of_a_runs_key_but_xfail_is_not():
    # Under anytime verdicts a run's result depends on its checkpoints and on its thresholds (it stops once met).
    once = sg.Budget(timesteps=1000, checkpoints=1)
    spec = sg.Spec(pendulum.initial_env, pendulum.trees["w"], budget=once, expect=0.5)
    anytime = spec.scaled(1, checkpoints=10)
    stricter = dataclasses.replace(anytime, expect={"pendulum": 0.6})
    expected_miss = dataclasses.replace(anytime, xfail={"pendulum": "why"})
    keys = [fingerprint_spec(s) for s in (spec, anytime, stricter, expected_miss)]
    assert len({k.run_key(0) for k in keys[:3]}) == 3
    assert keys[3].run_key(0) == keys[1].run_key(0) and keys[3].spec_key != keys[1].spec_key


def test_the_source_digest_sees_every_module_of_every_subpackage(tmp_path):
    import shutil

    from specguard.cache.versions import source_digest

    package = tmp_path / "specguard"
    shutil.copytree(Path(sg.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__"))
    before = source_digest(package)
    deep = package / "engine" / "run_spec.py"
    deep.write_text(deep.read_text() + "\n# edited\n")
    edited = source_digest(package)
    assert edited != before  # a module two folders down counts
    (package / "engine" / "run_spec.py").rename(package / "engine" / "moved.py")
    assert source_digest(package) != edited  # so does where it lies
    assert len({source_digest(package), source_digest(package)}) == 1  # and it is stable


def test_the_run_key_uses_the_digest_of_the_installed_package():
    from specguard.cache.versions import source_digest, versions

    assert versions()["specguard"] == f"{sg.__version__}+{source_digest(Path(sg.__file__).parent)}"
