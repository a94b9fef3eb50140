"""The constructed environment: Gymnasium API, docs/semantics.md on real and replayed envs."""

from __future__ import annotations

import copy
import pickle
import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from hypothesis import given, reject
from hypothesis import strategies as st
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import specguard as sg
from example_specs import acrobot, lunar_lander, mountain_car, pendulum
from specguard import strategies as sgst
from specguard.construction.env import BaselineEnv, make_baseline_env
from specguard.error import GoalMetAtStart, UnreachableGoal
from specguard.starts.space import START_OPTION, starts_of
from specguard.testing import ReplayEnv

CASES = [(m, key) for m in (acrobot, pendulum, mountain_car, lunar_lander) for key in m.trees]
IDS = [f"{m.__name__.split('.')[-1]}-{key}" for m, key in CASES]


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize(("module", "key"), CASES, ids=IDS)
def test_case_study_envs_pass_both_checkers(module, key):
    env = sg.make_env(module.initial_env, module.trees[key])
    gym_check_env(env)  # also re-creates the env from env.spec
    sb3_check_env(env, warn=False)
    env.close()


@pytest.mark.parametrize(("module", "key"), CASES, ids=IDS)
def test_case_study_rollout_reports_goals_and_terms(module, key):
    env = sg.make_env(module.initial_env, module.trees[key])
    obs, info = env.reset(seed=1)
    assert set(info["goals"]) == {p for p, _ in module.trees[key].walk()}
    env.action_space.seed(1)
    for _ in range(50):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert type(reward) is float and type(terminated) is bool and type(truncated) is bool
        assert obs in env.observation_space
        assert sum(info["reward_terms"].values()) == pytest.approx(reward)
        assert isinstance(info["base_reward"], float)
        if terminated or truncated:
            break
    env.close()


def test_env_is_recreated_from_its_spec():
    env = sg.make_env(pendulum.initial_env, pendulum.trees["w"])
    again = gym.make(env.spec)
    assert isinstance(again, sg.SpecEnv)
    assert again.tree == env.tree
    rollouts = []
    for e in (env, again):
        e.reset(seed=3)
        rollouts.append([e.step(np.array([0.5], dtype=np.float32))[1] for _ in range(20)])
    assert rollouts[0] == rollouts[1]


@pytest.mark.slow
def test_env_works_with_sb3_vector_envs():
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    for cls in (None, SubprocVecEnv):
        kwargs = {} if cls is None else {"vec_env_cls": cls}
        venv = make_vec_env(lambda: sg.make_env(pendulum.initial_env, pendulum.trees["c"]), n_envs=2, seed=0, **kwargs)
        obs = venv.reset()
        assert obs.shape == (2, 3)
        _, _, _, infos = venv.step(np.zeros((2, 1), dtype=np.float32))
        assert "pendulum/position:distance" in infos[0]["reward_terms"]
        venv.close()


@pytest.mark.slow
def test_a_factory_that_has_compiled_its_tree_builds_subprocess_envs():
    # The factory travels pickled (cloudpickle) with its compiled tree, less the generated code object.
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv

    from specguard.construction.env import EnvFactory

    build = EnvFactory(pendulum.initial_env, pendulum.trees["c"])
    build().close()
    assert build.compiled is not None and "code" in build.compiled.__dict__
    rewards = []
    for cls in (None, SubprocVecEnv):
        venv = make_vec_env(build, n_envs=2, seed=0, **({} if cls is None else {"vec_env_cls": cls}))
        venv.reset()
        rewards.append(venv.step(np.full((2, 1), 0.5, dtype=np.float32))[1].tolist())
        venv.close()
    assert rewards[0] == pytest.approx(rewards[1], rel=1e-6)  # DummyVecEnv keeps rewards in float32


def test_reference_and_flat_envs_give_the_same_rollout():
    rollouts = []
    for evaluator in ("flat", "reference"):
        env = sg.make_env(lunar_lander.initial_env, lunar_lander.trees["w"], evaluator=evaluator)
        env.reset(seed=7)
        env.action_space.seed(7)
        steps = []
        for _ in range(300):
            obs, r, te, tr, info = env.step(env.action_space.sample())
            steps.append((obs.tolist(), r, te, tr, info["goals"]))
            if te or tr:
                break
        rollouts.append(steps)
    assert len(rollouts[0]) == len(rollouts[1])
    for a, b in zip(*rollouts):
        assert a[0] == b[0] and a[2:] == b[2:]
        assert a[1] == pytest.approx(b[1], rel=1e-9, abs=1e-12)


def test_base_termination_and_truncation_are_kept():
    # Reachable (inside the observation bounds) but never reached by a pendulum left hanging.
    never = sg.Goal("never", x=(0.9999, None), omega=(7.9, None))
    env = sg.make_env(pendulum.initial_env, never)
    env.reset(seed=0)
    steps = 0
    truncated = False
    while not truncated:
        _, _, terminated, truncated, _ = env.step(np.zeros(1, dtype=np.float32))
        assert not terminated
        steps += 1
    assert steps == 200  # Pendulum-v1's TimeLimit

    lander = sg.make_env(lunar_lander.initial_env, sg.Goal("never", x=(0.9, None), leg1=1))  # far right, landed
    lander.reset(seed=0)
    for _ in range(1000):
        _, _, terminated, truncated, _ = lander.step(0)  # falls and crashes: the base env ends it
        if terminated or truncated:
            break
    assert terminated


def _replay(trajectory, tree, features):
    initial = sg.InitialEnv(lambda: ReplayEnv(trajectory), features=features)
    try:
        return sg.make_env(initial, tree)
    except UnreachableGoal:
        reject()  # drawn trees may hold an All whose children's boxes do not meet: refused before any step
    except GoalMetAtStart:  # a replay starts alike at every reset: refused by make_env, still an env to step
        return sg.SpecEnv(ReplayEnv(trajectory), tree=tree, features=features)


FEATURES = ("a", "b")


@given(sgst.trees(FEATURES), sgst.trajectories(FEATURES, max_size=15), st.data())
def test_observations_counters_and_termination(tree, trajectory, data):
    env = _replay(trajectory, tree, FEATURES)
    keys = env.evaluator.slots
    obs, info = env.reset(seed=0)
    assert obs in env.observation_space
    assert obs[2:].tolist() == [slot.high for _, slot in env.evaluator.slots]
    previous = obs[2:]
    for _ in trajectory[1:]:
        obs, _, terminated, truncated, info = env.step(data.draw(st.integers(0, 2)))
        assert obs in env.observation_space
        counters = obs[2:]
        assert len(counters) == len(keys)
        assert np.all(counters <= previous) and np.all(counters >= 0)  # never increase
        assert terminated == (info["goals"][tree.name] or bool(np.any(counters == 0)))
        previous = counters
        if terminated or truncated:
            break


def test_constraint_counter_ends_the_episode_exactly_at_zero():
    high = sg.Constraint(lambda s, a: s.a > 0.5, budget=2, name="high")
    tree = sg.Goal("g", b=(10.0, None)).annotate(high)
    trajectory = [[1.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]]
    env = _replay(trajectory, tree, FEATURES)
    obs, _ = env.reset()
    seen = [(obs[2], False)]
    for _ in range(5):
        obs, _, terminated, _, info = env.step(0)
        seen.append((obs[2], terminated))
        if terminated:
            break
    # Violations are judged on (s, a): s_0 and s_2 have a > 0.5.
    assert seen == [(2.0, False), (1.0, False), (1.0, False), (0.0, True)]
    assert info["reward_terms"]["g:high"] == -1.0


def test_execute_maps_actions_and_action_space_is_declared():
    seen = []

    def execute(a):
        seen.append(a)
        return np.array([2.0 * (a - 1)], dtype=np.float32)

    initial = sg.InitialEnv(
        "Pendulum-v1", features=("x", "y", "omega"), execute=execute, action_space=gym.spaces.Discrete(3)
    )
    env = sg.make_env(initial, pendulum.trees["b"])
    assert env.action_space == gym.spaces.Discrete(3)
    env.reset(seed=0)
    env.step(2)
    assert seen == [2]


def test_state_of_wrong_length_is_reported():
    initial = sg.InitialEnv("Pendulum-v1", features=("x", "y"), state=lambda o: o[:3])
    with pytest.raises(
        sg.error.StateMappingError, match=r"state\(\) must return 2 finite numbers for features \('x', 'y'\)"
    ):
        sg.make_env(initial, sg.Goal("g", x=(0, 1)))  # the start check reads the starts' features


def test_state_with_non_finite_values_is_reported():
    initial = sg.InitialEnv("Pendulum-v1", features=("x",), state=lambda o: [float("nan")])
    with pytest.raises(sg.error.StateMappingError, match=r"must return 1 finite numbers .* got \[nan\]"):
        sg.make_env(initial, sg.Goal("g", x=(0, 1)))  # the start check reads the starts' features


def test_state_that_raises_is_reported():
    initial = sg.InitialEnv("Pendulum-v1", features=("x",), state=lambda o: o["x"])
    with pytest.raises(sg.error.StateMappingError, match=r"g: state\(\) raised IndexError"):
        sg.make_env(initial, sg.Goal("g", x=(0, 1)))  # the start check reads the starts' features


def test_identity_state_needs_one_feature_per_observation():
    initial = sg.InitialEnv("Pendulum-v1", features=("x", "y"))
    with pytest.raises(
        sg.error.StateMappingError, match=r"identity state\(\) needs a flat Box observation of 2 features"
    ):
        sg.make_env(initial, sg.Goal("g", x=(0, 1)))


@pytest.mark.parametrize("make", [sg.make_env, make_baseline_env])
@pytest.mark.parametrize(
    ("features", "given"),
    [
        (("a", "b", "c", "d", "e"), "5 features ('a', 'b', 'c', 'd', 'e')"),
        (("a", "b", "c"), "3 features ('a', 'b', 'c')"),
    ],
)
def test_identity_state_features_must_label_the_observation_one_to_one(make, features, given):
    initial = sg.InitialEnv("CartPole-v1", features=features)
    with pytest.raises(sg.error.StateMappingError) as info:
        make(initial, sg.Goal("g", a=(0, 1)))
    message = str(info.value)
    assert message.startswith(f"InitialEnv 'CartPole-v1': the identity state() needs a flat Box observation of {given}")
    assert "but the observation has 4 components" in message
    assert "Hint: name exactly 4 features, or compute the features in state=..." in message


def test_identity_state_rejects_a_non_box_observation_early():
    initial = sg.InitialEnv("FrozenLake-v1", features=("cell",))
    with pytest.raises(
        sg.error.StateMappingError, match=r"InitialEnv 'FrozenLake-v1': .* the observation space is Discrete\(16\)"
    ):
        make_baseline_env(initial, sg.Goal("g", cell=(0, 1)))


def test_unknown_feature_fails_before_the_env_is_built():
    with pytest.raises(
        sg.error.UnknownFeature, match=r"pendulum/speed: goal names unknown feature 'v'; known features: x, y, omega"
    ):
        sg.make_env(pendulum.initial_env, sg.All(sg.Goal("speed", v=(0, 1)), name="pendulum"))


def test_make_env_rejects_wrong_argument_types():
    with pytest.raises(sg.error.InitialEnvError, match="expected an InitialEnv"):
        sg.make_env("Pendulum-v1", pendulum.trees["a"])
    with pytest.raises(sg.error.InvalidSpec, match=r"expected a goal-tree node \(Goal, All, ...\) as tree"):
        sg.make_env(pendulum.initial_env, {"x": (0, 1)})
    with pytest.raises(sg.error.InvalidSpec, match="expected 'flat' or 'reference'"):
        sg.make_env(pendulum.initial_env, pendulum.trees["a"], evaluator="fast")


@pytest.mark.parametrize("make", [sg.make_env, make_baseline_env])
@pytest.mark.parametrize(
    ("initial", "tree", "error", "message"),
    [
        ("Pendulum-v1", pendulum.trees["a"], sg.error.InitialEnvError, "expected an InitialEnv as first argument"),
        (
            pendulum.initial_env,
            {"x": (0, 1)},
            sg.error.InvalidSpec,
            r"expected a goal-tree node \(Goal, All, ...\) as tree",
        ),
        (pendulum.initial_env, sg.Goal("g", v=(0, 1)), sg.error.UnknownFeature, "goal names unknown feature 'v'"),
    ],
    ids=["not-an-initial-env", "not-a-node", "unknown-feature"],
)
def test_the_baseline_env_refuses_what_make_env_refuses(make, initial, tree, error, message):
    # One preflight for both (issue 19): the baseline used to skip the node check.
    with pytest.raises(error, match=message) as info:
        make(initial, tree)
    if error is not sg.error.UnknownFeature:  # the argument checks name the function called
        assert str(info.value).startswith(make.__name__)


@pytest.mark.parametrize("make", [sg.make_env, make_baseline_env])
def test_make_env_compiles_and_generates_the_tree_once(build_counts, make):
    env = make(lunar_lander.initial_env, lunar_lander.trees["c"])
    assert build_counts == {"compile": 1, "codegen": 1}
    env.close()


def test_envs_of_one_factory_share_the_compiled_tree_but_not_the_episode(build_counts):
    from specguard.construction.env import EnvFactory

    build = EnvFactory(pendulum.initial_env, pendulum.trees["w"])
    first, second = build(), build()
    assert build_counts == {"compile": 1, "codegen": 1}
    assert first.compiled is second.compiled and first.evaluator is not second.evaluator
    first.reset(seed=0)
    second.reset(seed=0)
    torque = np.array([2.0], dtype=np.float32)
    for _ in range(5):
        step = first.step(torque)
    # The second env's episode is its own: stepping it now gives what the first gave at its first step.
    again = sg.make_env(pendulum.initial_env, pendulum.trees["w"])
    again.reset(seed=0)
    assert second.step(torque)[1] == again.step(torque)[1] != step[1]


def test_info_deep_copies_without_walking_its_scalars_and_stays_independent(monkeypatch):
    # SB3's DummyVecEnv deep-copies every info at every step; the goals/safe/reward-term dicts and the base reward
    # hold scalars only, so the info's deep copy walks none of them (one call, no item-by-item copy), and is still
    # a copy a consumer may change.
    env = sg.make_env(lunar_lander.initial_env, lunar_lander.trees["w"])
    env.reset(seed=0)
    info = env.step(env.action_space.sample())[4]
    walked: list[object] = []
    atomic = copy._deepcopy_dispatch[bool]
    for kind in (bool, float, str):
        monkeypatch.setitem(copy._deepcopy_dispatch, kind, lambda x, memo: walked.append(x) or atomic(x, memo))
    copied = copy.deepcopy(info)
    assert walked == []
    assert copied == info and type(copied) is type(info)
    for key in ("goals", "safe", "reward_terms"):
        assert copied[key] == info[key] and copied[key] is not info[key]
        copied[key]["mutated"] = True
        assert "mutated" not in info[key]
    assert pickle.loads(pickle.dumps(info)) == info  # SubprocVecEnv sends infos between processes
    env.close()


def test_an_info_deep_copy_copies_what_is_not_scalar_as_deepcopy_does():
    from specguard.construction.env import StepInfo

    shared = {"x": [1.0]}
    frame = np.zeros(3)
    info = StepInfo(
        goals={"a": True}, episode={"r": 1.0, "l": 5}, obs=frame, nested=shared, again=shared, terms={("k",): 1.0}
    )
    copied = copy.deepcopy(info)
    assert copied.keys() == info.keys() and copied["goals"] == {"a": True} and copied["episode"] == info["episode"]
    assert copied["obs"] is not frame and np.array_equal(copied["obs"], frame)
    assert copied["nested"] is copied["again"] is not shared  # one copy of a shared object, as deepcopy makes
    assert copied["nested"]["x"] is not shared["x"]
    assert copied["terms"] == {("k",): 1.0}
    info_of_env = {"raw": [1]}

    class Env(gym.Env):
        observation_space = gym.spaces.Box(-1.0, 1.0, (1,))
        action_space = gym.spaces.Discrete(2)

        def reset(self, *, seed=None, options=None):
            return np.zeros(1, dtype=np.float32), info_of_env

        def step(self, action):
            return np.zeros(1, dtype=np.float32), 0.0, False, False, info_of_env

    env = sg.SpecEnv(Env(), sg.Goal("g", x=(0.5, None)), ("x",))
    assert "goals" in env.reset(seed=0)[1] and "goals" in env.step(0)[4]
    assert info_of_env == {"raw": [1]}  # the initial env's own info is left as it was


@pytest.mark.parametrize("tree", [lunar_lander.trees["c"], sg.Goal("legs", leg1=1.0)], ids=["own-state", "passthrough"])
def test_what_a_step_returns_is_never_changed_by_a_later_step(tree):
    # Consumers keep references (SB3's DummyVecEnv keeps the last observation as info["terminal_observation"]
    # across the reset): every observation and info dict is a new object, never a reused buffer.
    env = sg.make_env(lunar_lander.initial_env, tree)
    obs, info = env.reset(seed=0)
    kept = [(obs, obs.copy(), info, {k: dict(v) if isinstance(v, dict) else v for k, v in info.items()})]
    env.action_space.seed(0)
    for _ in range(30):
        obs, _, terminated, truncated, info = env.step(env.action_space.sample())
        kept.append((obs, obs.copy(), info, {k: dict(v) if isinstance(v, dict) else v for k, v in info.items()}))
        info["goals"]["mutated"] = True  # a consumer writing into its info changes nothing that follows
        if terminated or truncated:
            obs, info = env.reset(seed=1)
    for obs, kept_obs, info, snapshot in kept:
        assert np.array_equal(obs, kept_obs)
        assert {k: v for k, v in info["goals"].items() if k != "mutated"} == snapshot["goals"]
        assert info["safe"] == snapshot["safe"]
    assert len({id(o) for o, *_ in kept}) == len(kept)
    assert len({id(info["goals"]) for _, _, info, _ in kept}) == len(kept)
    env.close()


def test_a_factory_refuses_again_what_its_preflight_refused():
    from specguard.construction.env import EnvFactory

    build = EnvFactory(pendulum.initial_env, sg.Goal("g", v=(0, 1)), baseline=True)
    for _ in range(2):
        with pytest.raises(sg.error.UnknownFeature, match="g: goal names unknown feature 'v'"):
            build()


def test_an_env_refuses_the_compiled_tree_of_another_tree():
    from specguard.construction.compiled import compile_tree

    base = gym.make("Pendulum-v1")
    other = compile_tree(pendulum.trees["b"], pendulum.initial_env.features)
    with pytest.raises(sg.error.InvalidSpec, match="compiled: expected compile_tree"):
        sg.SpecEnv(base, pendulum.trees["w"], pendulum.initial_env.features, compiled=other)
    with pytest.raises(sg.error.InvalidSpec, match="compiled: expected compile_tree"):
        BaselineEnv(base, pendulum.trees["w"], pendulum.initial_env.features, compiled=other)
    tree = sg.All(sg.Goal("a", x=(0.9, 1.0)), sg.Goal("b", omega=(-1, 1)), name="auto", weights="auto")
    adapted = compile_tree(tree, pendulum.initial_env.features, weights={"auto": (0.7, 0.3)})
    with pytest.raises(sg.error.InvalidSpec, match="compiled: expected the tree compiled with its own weights"):
        sg.SpecEnv(base, tree, pendulum.initial_env.features, compiled=adapted)


def test_acrobot_height_feature_comes_from_state():
    env = sg.make_env(acrobot.initial_env, acrobot.trees["c"])
    obs, _ = env.reset(seed=0)
    cos1, sin1, cos2, sin2 = obs[:4]
    assert obs[6] == pytest.approx(-cos1 - (cos1 * cos2 - sin1 * sin2), abs=1e-6)
    assert env.observation_space.low[6] == -2.0 and env.observation_space.high[6] == 2.0


def test_baseline_env_keeps_the_initial_env_and_reports_goals():
    baseline = make_baseline_env(acrobot.initial_env, acrobot.trees["c"])
    raw = gym.make("Acrobot-v1")
    (obs_b, info_b), (obs_r, _) = baseline.reset(seed=4), raw.reset(seed=4)
    assert obs_b.tolist() == obs_r.tolist() and info_b["goals"] == {"height": False}
    for _ in range(20):
        step_b, step_r = baseline.step(1), raw.step(1)
        assert step_b[0].tolist() == step_r[0].tolist() and step_b[1:4] == step_r[1:4]
        assert set(step_b[4]["goals"]) == {"height"}
    gym_check_env(baseline, skip_render_check=True)


class NanReward(gym.Wrapper):
    def step(self, action):
        obs, _, terminated, truncated, info = self.env.step(action)
        return obs, float("nan"), terminated, truncated, info


def test_baseline_env_rejects_non_finite_rewards():
    initial = sg.InitialEnv(lambda: NanReward(gym.make("Pendulum-v1")), features=("x", "y", "omega"))
    env = make_baseline_env(initial, pendulum.trees["b"])
    env.reset(seed=0)
    with pytest.raises(sg.error.EvaluationError, match=r"pendulum: the initial env returned a non-finite reward nan"):
        env.step(np.zeros(1, dtype=np.float32))


def _replay_auto_env(**kwargs):
    initial = sg.InitialEnv(lambda: ReplayEnv([[0.0], [1.0], [0.0], [1.0]]), features=("x",))
    tree = sg.All(sg.Goal("up", x=(0.5, None)), sg.Goal("low", x=(None, 0.7)), name="p", weights="auto")
    return sg.make_env(initial, tree, **kwargs)


def test_adapted_weights_apply_from_the_next_episode_on():
    env = _replay_auto_env()
    env.reset(seed=0)
    assert env.step(0)[1] == pytest.approx(0.0)  # 0 -> 1: enters "up" (+1/2), leaves "low" (-1/2)
    env.set_weights({"p": (0.9, 0.1)})
    assert env.step(0)[1] == pytest.approx(0.0)  # mid-episode: the weights it started with
    assert env.adapted_weights == {}
    env.reset(seed=0)
    assert env.adapted_weights == {"p": (0.9, 0.1)}
    assert env.step(0)[1] == pytest.approx(0.9 - 0.1)
    with pytest.raises(sg.error.InvalidSpec, match=r"weights\['p/up'\]"):
        env.set_weights({"p/up": (1.0,)})


def test_the_reference_evaluator_keeps_the_trees_weights():
    with pytest.raises(sg.error.InvalidSpec, match=r"evaluator: adapted weights need the 'flat' evaluator"):
        _replay_auto_env(evaluator="reference").set_weights({"p": (0.9, 0.1)})


@pytest.mark.parametrize(
    "returns, shown",
    [
        (lambda s, a: None, "None (NoneType)"),
        (lambda s, a: "yes", "'yes' (str)"),
        (lambda s, a: np.array([1, 2]), "(ndarray)"),
    ],
    ids=["forgot return", "a string", "an array"],
)
@pytest.mark.parametrize("evaluator", ["flat", "reference"])
def test_a_constraint_that_returns_no_truth_value_is_an_error_naming_it(returns, shown, evaluator):
    tree = sg.Goal("up", x=(0.9, 1.0)).annotate(sg.Constraint(returns, name="fast"))
    env = sg.make_env(pendulum.initial_env, tree, evaluator=evaluator)
    env.reset(seed=0)
    with pytest.raises(sg.error.EvaluationError, match=r"fast.*the constraint function returned .*" + re.escape(shown)):
        env.step(np.zeros(1, dtype=np.float32))


def test_a_constraint_returning_numpy_bools_is_fine_in_every_evaluator():
    tree = sg.Goal("up", x=(0.9, 1.0)).annotate(sg.Constraint(lambda s, a: np.bool_(s.x > 2.0), name="never"))
    for evaluator in ("flat", "reference"):
        env = sg.make_env(pendulum.initial_env, tree, evaluator=evaluator)
        env.reset(seed=0)
        for _ in range(3):
            _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
        assert info["safe"] == {"up:never": True}


def _raises_at_build():
    raise ZeroDivisionError("boom")


@pytest.mark.parametrize(
    "initial, names",
    [
        (lambda: sg.InitialEnv(_raises_at_build, features=("x",)), r"_raises_at_build: building it with its factory"),
        (
            lambda: sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"), nonsense=3),
            r"'Pendulum-v1': building it with gymnasium.make and \{'nonsense': 3\} raised TypeError",
        ),
        (
            lambda: sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"), execute=lambda a: 1 / 0),
            r"g: execute\(\) raised ZeroDivisionError: division by zero on action",
        ),
    ],
    ids=["factory", "make keyword", "execute"],
)
def test_factory_make_and_execute_errors_are_spec_errors_naming_the_culprit(initial, names):
    with pytest.raises(sg.error.InitialEnvError, match=names):
        env = sg.make_env(initial(), sg.Goal("g", x=(0.9, 1.0)))
        env.reset(seed=0)
        env.step(np.zeros(1, dtype=np.float32))


# -- action masks ----------------------------------------------------------------------------


class MaskedCartPole(gym.Wrapper):
    """CartPole whose masks allow only pushing left while the cart is right of the middle."""

    def __init__(self):
        super().__init__(gym.make("CartPole-v1"))

    def action_masks(self):
        return np.array([True, self.unwrapped.state[0] <= 0])


CARTPOLE_FEATURES = ("x", "v", "theta", "omega")
FAR = sg.Goal("far", x=(2.0, 2.4))


def test_the_constructed_env_gives_the_initial_envs_masks_through_any_wrapper():
    from sb3_contrib.common.maskable.utils import get_action_masks, is_masking_supported
    from stable_baselines3.common.env_util import make_vec_env

    from specguard.construction.env import action_masks_problem

    env = sg.make_env(sg.InitialEnv(MaskedCartPole, features=CARTPOLE_FEATURES), FAR)
    obs, _ = env.reset(seed=0)
    assert action_masks_problem(env) is None
    assert list(env.action_masks()) == [True, bool(obs[0] <= 0)]
    venv = make_vec_env(lambda: sg.make_env(sg.InitialEnv(MaskedCartPole, features=CARTPOLE_FEATURES), FAR), 2)
    obs = venv.reset()
    assert is_masking_supported(venv)  # as sb3-contrib reads them: through SB3's Monitor and the vec env
    assert get_action_masks(venv).tolist() == [[True, bool(x <= 0)] for x in obs[:, 0]]


@pytest.mark.parametrize(
    ("kwargs", "problem"),
    [
        ({}, r"the initial env \(CartPoleEnv\) has no action_masks\(\) method"),
        ({"execute": lambda a: 1 - a}, r"the agent's actions go through execute\(\)"),
    ],
)
def test_an_env_without_masks_for_the_agents_actions_says_why(kwargs, problem):
    from specguard.construction.env import action_masks_problem

    factory = MaskedCartPole if kwargs else (lambda: gym.make("CartPole-v1"))
    env = sg.make_env(sg.InitialEnv(factory, features=CARTPOLE_FEATURES, **kwargs), FAR)
    env.reset(seed=0)
    assert re.match(problem, action_masks_problem(env))
    with pytest.raises(sg.error.InitialEnvError, match=rf"far: no action masks: {problem}"):
        env.action_masks()


# -- a start space given to the factory ---------------------------------------------------------

CARTPOLE = sg.InitialEnv("CartPole-v1", features=CARTPOLE_FEATURES)
WIDE = sg.StartSpace({"x": (-1.0, 1.0), "theta": (-0.2, 0.2)})


@pytest.mark.parametrize(
    "make",
    [
        lambda **kw: sg.make_env(CARTPOLE, FAR, **kw),
        lambda **kw: make_baseline_env(CARTPOLE, FAR, **kw),
        lambda **kw: sg.Spec(CARTPOLE, FAR, budget=sg.Budget(timesteps=64), expect=0.5).make_env(**kw),
    ],
    ids=["make_env", "make_baseline_env", "Spec.make_env"],
)
def test_an_env_made_with_a_start_space_starts_where_it_is_told_in_that_space(make):
    env = make(starts=WIDE)
    starts = starts_of(env)  # resolved over the base env as it was made
    assert starts.names == CARTPOLE_FEATURES and starts.low.tolist() == [-1.0, -0.05, -0.2, -0.05]
    for point in starts.uniform(np.random.default_rng(0), 5):
        obs, info = env.reset(seed=0, options={START_OPTION: starts.values(point)})
        np.testing.assert_allclose(obs[:4], point, atol=1e-6)  # the first state is the start asked for
        assert info["goals"] == {"far": False}  # judged there, as the spec's env judges any reset
    obs, _ = env.reset(seed=3)  # no start asked for: the env's own reset
    np.testing.assert_array_equal(obs[:4], gym.make("CartPole-v1").reset(seed=3)[0])


def test_an_env_made_without_a_start_space_has_none_and_a_wrong_one_is_refused_naming_it():
    with pytest.raises(
        sg.error.InvalidSpec, match=r"CartPole-v1: the env has no StartWrapper .* without a start space"
    ):
        starts_of(sg.make_env(CARTPOLE, FAR))
    assert starts_of(sg.make_env(CARTPOLE, FAR, starts={"x": (-1.0, 1.0)})).high.tolist() == [1.0, 0.05, 0.05, 0.05]
    with pytest.raises(
        sg.error.InvalidSpec, match=r"^make_env: expected starts to be a StartSpace or \{name: \(lo, hi\)\}"
    ):
        sg.make_env(CARTPOLE, FAR, starts=5)
    with pytest.raises(sg.error.UnknownFeature, match=r"the start space names 'height'"):
        make_baseline_env(CARTPOLE, FAR, starts={"height": (0.0, 1.0)})
