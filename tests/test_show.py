"""Look before you train: `--goal-specs-show`, `specguard show` on a pytest file, and budget rounding."""

from __future__ import annotations

import sys
import textwrap
import warnings

import pytest

import specguard as sg
from specguard.report.show import has_goal_specs, render_spec
from specguard.spec.budget import trained_timesteps

SPECS = textwrap.dedent(
    """
    import pytest
    import specguard as sg


    @pytest.fixture
    def cartpole():
        return sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))


    @sg.goal_spec(expect={"balance": 0.8, "upright": 0.9})
    def test_balance(cartpole):
        upright = sg.Goal("upright", theta=(-0.05, 0.05)).annotate(
            sg.Constraint(lambda s, a: abs(s.omega) > 2.0, budget=3, name="no_spin")
        )
        tree = sg.All(sg.Goal("right", x=(0.5, 1.5)), upright, name="balance")
        return sg.Spec(cartpole, tree, budget=sg.Budget(timesteps=512))
    """
)

EXPECTED = [
    "== test_cartpole_specs.py::test_balance",
    "InitialEnv('CartPole-v1', features=('x', 'v', 'theta', 'omega')), PPO, constructed env",
    "All 'balance'",
    "├── Goal 'right': 0.5 <= x <= 1.5",
    "R = 0.5*R[right] + 0.5*(R[upright] + P[upright:no_spin])",
    "observation: 5 components (features, then the own state of nodes and annotations)",
    "  x                                [-4.8, 4.8]",
    "  theta                            [-0.418879, 0.418879]",
    "  counter balance/upright:no_spin  [0, 3]",
    "budget: 2048 timesteps per seed (512 asked, rounded up to whole PPO rollouts of 2048 = 2048 steps x 1 env), "
    "2 seeds, 30 eval episodes (up to 120); judged at 10 checkpoints, training stops once every threshold is met",
    "expect: balance >= 0.8, balance/upright >= 0.9",
]


@pytest.fixture
def spec_file(pytester):
    pytester.makeini("[pytest]\ngoal_specs_workers = 1\n")
    return pytester.makepyfile(test_cartpole_specs=SPECS)


def test_goal_specs_show_prints_each_spec_once_and_trains_nothing(pytester, spec_file):
    cache = pytester.path / "cache"
    result = pytester.runpytest_subprocess(
        "-p", "no:cacheprovider", f"--goal-specs-cache-dir={cache}", "--goal-specs", "--goal-specs-show", "-rs"
    )
    result.assert_outcomes(skipped=2, warnings=1)
    out = result.stdout.str()
    for line in EXPECTED:
        assert line in out.splitlines(), line
    assert out.count("== test_cartpole_specs.py::test_balance") == 1  # two goal items, one spec
    assert "shown, not trained" in out
    assert "budget of 512 timesteps trains 2048" in out  # the rounding warning, once
    assert not cache.exists()  # nothing trained, nothing cached


def test_goal_specs_show_fails_a_refused_spec_without_training(pytester):
    pytester.makepyfile(
        test_far="""
        import specguard as sg

        @sg.goal_spec(expect=0.5)
        def test_far():
            cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
            return sg.Spec(cartpole, sg.Goal("far", x=(10, None)), budget=sg.Budget(timesteps=2048))
        """
    )
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "--goal-specs", "--goal-specs-show")
    result.assert_outcomes(failed=1)
    result.stdout.fnmatch_lines(["*test_far.py::test_far*far: goal box x in [[]10, inf] lies outside the bounds*"])


def test_specguard_show_on_a_pytest_goal_spec_file_resolves_its_fixtures(pytester, spec_file):
    assert has_goal_specs(spec_file)
    result = pytester.run(sys.executable, "-m", "specguard", "show", str(spec_file))
    assert result.ret == 0, result.stdout.str() + result.stderr.str()
    out = result.stdout.str()
    for line in EXPECTED:
        assert line in out.splitlines(), line
    assert "defines no" not in out + result.stderr.str()
    assert not (pytester.path / ".specguard").exists()


def test_render_spec_is_the_one_rendering():
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    once = sg.Budget(timesteps=4096, checkpoints=1)
    spec = sg.Spec(cartpole, sg.Goal("right", x=(0.5, 1.5)), budget=once, trainer=sg.SB3(n_envs=2))
    text = render_spec(spec, "mine")
    assert text.splitlines()[0] == "== mine"
    assert "budget: 4096 timesteps per seed (2 envs), 2 seeds, 30 eval episodes (up to 120)" in text.splitlines()
    assert "observation: 4 components" in text
    anytime = render_spec(spec.scaled(1, checkpoints=4))
    budget = next(line for line in anytime.splitlines() if line.startswith("budget:"))
    assert budget.endswith("; judged at 4 checkpoints, training stops once every threshold is met")


def test_render_spec_names_each_expected_miss_with_its_reason():
    cartpole = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    tree = sg.All(sg.Goal("right", x=(0.5, 1.5)), sg.Goal("upright", theta=(-0.05, 0.05)), name="balance")
    spec = sg.Spec(
        cartpole,
        tree,
        budget=sg.Budget(timesteps=4096),
        expect={"balance": 0.8, "upright": 0.9},
        xfail={"upright": "paper: not learned"},
    )
    lines = render_spec(spec).splitlines()
    assert lines[-2:] == [
        "expect: balance >= 0.8, balance/upright >= 0.9",
        "xfail: balance/upright may miss (paper: not learned)",
    ]
    plain = sg.Spec(cartpole, tree, budget=sg.Budget(timesteps=4096), expect={"balance": 0.8, "upright": 0.9})
    assert not any(line.startswith("xfail:") for line in render_spec(plain).splitlines())


@pytest.mark.parametrize(
    ("timesteps", "algorithm", "hyperparameters", "n_envs", "trained"),
    [
        (512, "PPO", {}, 1, 2048),
        (4096, "PPO", {}, 2, 4096),
        (100_000, "PPO", {"n_steps": 1024}, 4, 102_400),
        (101, "A2C", {}, 4, 120),
        (100, "A2C", {}, 4, 100),
        (10, "DQN", {}, 1, 12),
        (10, "SAC", {}, 3, 12),
        (10, "SAC", {"train_freq": (2, "step")}, 1, 10),
    ],
)
def test_trained_timesteps_round_up_to_whole_collections(timesteps, algorithm, hyperparameters, n_envs, trained):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert trained_timesteps(sg.Budget(timesteps=timesteps), algorithm, hyperparameters, n_envs) == trained


def test_rounding_up_by_more_than_ten_percent_warns_once():
    with pytest.warns(UserWarning, match=r"budget of 512 timesteps trains 2048: PPO collects 2048 steps") as seen:
        assert trained_timesteps(512, "PPO", {}, 1) == 2048
    assert len(seen) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert trained_timesteps(1900, "PPO", {}, 1) == 2048  # 7.8% more: no warning


def test_the_budget_the_docs_give_an_agent_check_is_shown_without_a_warning(tmp_path, capsys):
    from specguard.cli.main import main

    (tmp_path / "agents.py").write_text(
        "import specguard as sg\n"
        "cartpole = sg.InitialEnv('CartPole-v1', features=('x', 'v', 'theta', 'omega'))\n"
        "keep = sg.Spec(cartpole, sg.Always(sg.Goal('upright', theta=(-0.2, 0.2)), name='balance'),\n"
        "               budget=sg.Budget(timesteps=1), expect=0.5)\n"
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # docs/guide/agents.md's Budget(timesteps=1): not a budget to round
        assert main(["show", str(tmp_path / "agents.py")]) == 0
    assert "budget: 2048 timesteps per seed (1 asked, rounded up" in capsys.readouterr().out
    with pytest.warns(UserWarning, match="budget of 2 timesteps trains 2048"):
        trained_timesteps(2, "PPO", {}, 1)  # any other small budget still warns
