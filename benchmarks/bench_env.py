"""Overhead of the constructed env over the raw env, measured in one run.

Steps the raw ``gym.make(env_id)`` env and the env constructed from a goal tree
in lockstep, with the same pre-sampled actions and the same reset seeds, so both
see the same states (when the constructed env ends an episode earlier, both are
reset). Then trains PPO with the same hyperparameters and seed on each and
compares throughput. Then steps ``--n-envs`` of each as training steps them (``make_vec_env`` of the raw env
against :func:`~specguard.training.vec_env.spec_vec_env`, the constructed envs stepped together), against the
same targets. Prints per-step times and ratios; exits 0 whatever the
figures (targets are reported, not asserted: machines are shared and noisy).

Targets (issue "the falsifier ahead of random on every agent, and the step cost"): LunarLander (c), with its
crash constraint, <= 1.10x, also written as a user writes it inline (distances as lambdas with ``math.hypot``,
the crash constraint of budget 1); Pendulum (w) <= 1.15x; a ``Sequence`` of three box goals with one distance
on CartPole <= 1.3x (a general node with own state, evaluated from its definition); MountainCarContinuous, a
reach goal with a distance and a constraint, <= 1.3x; PPO throughput on the constructed env >= 0.9x the raw
env's. The verdict is on the median ratio of the rounds; the best round's ratio is printed beside it (on a
shared machine, the round least disturbed by other work).

Usage:
    python benchmarks/bench_env.py [--steps 20000] [--rounds 5] [--ppo-steps 8192] [--skip-ppo] [--n-envs 16]
        [--case Lunar]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import specguard as sg

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # the case studies live beside the package
from example_specs import acrobot, lunar_lander, mountain_car, pendulum


def _cartpole_sequence() -> tuple[sg.InitialEnv, sg.Node]:
    """CartPole: right, then left, then the centre, one distance on the first stage (plugins/ must be installed)."""
    from specguard_plugins import Sequence

    initial_env = sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega"))
    right = sg.Goal("right", x=(0.5, None)).annotate(sg.Distance(lambda s: abs(s.x - 0.5), scale=3.0))
    left = sg.Goal("left", x=(None, -0.5))
    centre = sg.Goal("centre", x=(-0.1, 0.1), theta=(-0.05, 0.05))
    return initial_env, Sequence(right, left, centre, name="tour")


def _lunar_lander_lambdas() -> tuple[sg.InitialEnv, sg.Node]:
    """LunarLander (c) as a user writes it inline: distances as lambdas with ``math.hypot``, the crash constraint."""
    goals = [sg.Goal(name, **bounds) for name, bounds in lunar_lander.BOUNDS.items()]
    position, velocity, stabilization, legs = goals
    tree = sg.All(
        position.annotate(sg.Distance(lambda s: math.hypot(s.x, s.y), scale=2.0)),
        velocity.annotate(sg.Distance(lambda s: math.hypot(s.vx, s.vy), scale=2.0)),
        stabilization.annotate(sg.Distance(lambda s: abs(s.angle), scale=math.pi)),
        legs,
        name="lander",
    ).annotate(sg.Constraint(lambda s, a: abs(s.x) >= 0.2 and s.y <= 0.2, budget=1, name="crash"))
    return lunar_lander.initial_env, tree


def _mountain_car_reach() -> tuple[sg.InitialEnv, sg.Node]:
    """MountainCarContinuous: reach the flag, with a distance to it and a constraint on the speed leaving it."""
    flag = sg.Goal("flag", x=(0.45, None)).annotate(sg.Distance(lambda s: max(0.0, 0.45 - s.x), scale=1.8))
    reckless = sg.Constraint(lambda s, a: s.x > 0.4 and s.vel > 0.05, budget=3, name="reckless")
    return mountain_car.initial_env, flag.annotate(reckless)


CASES: list[tuple[str, Callable[[], tuple[sg.InitialEnv, sg.Node]], float | None]] = [
    # (label, initial env and tree, target ratio)
    ("Pendulum (w)", lambda: (pendulum.initial_env, pendulum.trees["w"]), 1.15),
    ("LunarLander (c)", lambda: (lunar_lander.initial_env, lunar_lander.trees["c"]), 1.10),
    ("LunarLander (c), lambdas", _lunar_lander_lambdas, 1.10),
    ("CartPole Sequence of 3", _cartpole_sequence, 1.3),
    ("MountainCarCont. reach", _mountain_car_reach, 1.3),
    ("Acrobot (c)", lambda: (acrobot.initial_env, acrobot.trees["c"]), None),
    ("MountainCarContinuous (c)", lambda: (mountain_car.initial_env, mountain_car.trees["c"]), None),
]


def lockstep(raw: gym.Env, built: gym.Env, actions: list[Any], seed: int) -> tuple[float, float]:
    """Seconds spent in ``step`` by each env over ``actions``, on identical trajectories."""
    t_raw = t_built = 0.0
    episode = seed
    raw.reset(seed=episode)
    built.reset(seed=episode)
    clock = time.perf_counter
    for a in actions:
        t0 = clock()
        _, _, te1, tr1, _ = raw.step(a)
        t1 = clock()
        _, _, te2, tr2, _ = built.step(a)
        t2 = clock()
        t_raw += t1 - t0
        t_built += t2 - t1
        if te1 or tr1 or te2 or tr2:
            episode += 1
            raw.reset(seed=episode)
            built.reset(seed=episode)
    return t_raw, t_built


def bench_steps(n_steps: int, rounds: int, only: list[str] | None = None) -> None:
    print(f"Per-step time, {n_steps} steps x {rounds} rounds, lockstep on the same states (median of rounds)")
    print(f"{'case':28s} {'raw us':>8s} {'built us':>9s} {'ratio':>7s} {'best':>7s} {'target':>7s}")
    for label, case, target in CASES:
        if only and not any(part.lower() in label.lower() for part in only):
            continue
        initial_env, tree = case()
        assert isinstance(initial_env.env, str)
        raw = gym.make(initial_env.env)
        built = sg.make_env(initial_env, tree)
        raw.action_space.seed(0)
        actions = [raw.action_space.sample() for _ in range(n_steps)]
        lockstep(raw, built, actions[: n_steps // 10], seed=10_000)  # warm-up
        raws, builts, ratios = [], [], []
        for r in range(rounds):
            t_raw, t_built = lockstep(raw, built, actions, seed=r * 1000)
            raws.append(t_raw / n_steps * 1e6)
            builts.append(t_built / n_steps * 1e6)
            ratios.append(t_built / t_raw)
        ratio = statistics.median(ratios)
        verdict = "" if target is None else f"<= {target}" + (" ok" if ratio <= target else " MISSED")
        print(
            f"{label:28s} {statistics.median(raws):8.2f} {statistics.median(builts):9.2f} {ratio:7.3f} "
            f"{min(ratios):7.3f} {verdict}"
        )
        raw.close()
        built.close()


def vec_steps(venv: Any, actions: list[np.ndarray]) -> float:
    """Seconds ``venv`` spends stepping through ``actions`` (one batch of actions per step), from a seeded reset."""
    venv.reset()
    clock = time.perf_counter
    start = clock()
    for a in actions:
        venv.step(a)
    return clock() - start


def bench_batched(n_envs: int, n_steps: int, rounds: int, only: list[str] | None = None) -> None:
    """Training's envs: ``n_envs`` raw envs in ``make_vec_env`` against the constructed ones in training's
    ``spec_vec_env`` (and, for the record, in ``make_vec_env``, as training stepped them before), same actions."""
    from stable_baselines3.common.env_util import make_vec_env

    from specguard.training.vec_env import spec_vec_env

    print(
        f"\nTraining's envs, {n_envs} envs x {n_steps // n_envs} steps x {rounds} rounds, per env step "
        "(median of rounds; raw: make_vec_env of gym.make)"
    )
    print(f"{'case':28s} {'raw us':>8s} {'each us':>8s} {'ratio':>7s} {'together':>9s} {'ratio':>7s} {'target':>7s}")
    for label, case, target in CASES:
        if only and not any(part.lower() in label.lower() for part in only):
            continue
        initial_env, tree = case()
        env_id = initial_env.env
        assert isinstance(env_id, str)
        build = partial(sg.make_env, initial_env, tree, check=False)
        venvs = {
            "raw": make_vec_env(partial(gym.make, env_id), n_envs=n_envs, seed=0),
            "each": make_vec_env(build, n_envs=n_envs, seed=0),
            "together": spec_vec_env(build, n_envs=n_envs, seed=0),
        }
        space = venvs["raw"].action_space
        space.seed(0)
        actions = [np.stack([space.sample() for _ in range(n_envs)]) for _ in range(n_steps // n_envs)]
        vec_steps(venvs["together"], actions[: len(actions) // 10])  # warm-up
        times: dict[str, list[float]] = {name: [] for name in venvs}
        for _ in range(rounds):
            for name, venv in venvs.items():
                times[name].append(vec_steps(venv, actions) / (len(actions) * n_envs) * 1e6)
        raw, each, together = (statistics.median(times[name]) for name in ("raw", "each", "together"))
        ratio = together / raw
        verdict = "" if target is None else f"<= {target}" + (" ok" if ratio <= target else " MISSED")
        print(f"{label:28s} {raw:8.2f} {each:8.2f} {each / raw:7.3f} {together:9.2f} {ratio:7.3f} {verdict}")
        for venv in venvs.values():
            venv.close()


def ppo_throughput(make: Callable[[], gym.Env], steps: int, kwargs: dict[str, Any]) -> float:
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", make(), seed=0, device="cpu", verbose=0, **kwargs)
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    return steps / (time.perf_counter() - start)


def bench_ppo(steps: int, rounds: int) -> None:
    import torch

    torch.set_num_threads(1)
    print(f"\nPPO training throughput, {steps} steps, SB3 defaults, seed 0, alternating, median of {rounds}")
    print(f"{'case':28s} {'raw steps/s':>12s} {'built steps/s':>14s} {'ratio':>7s} {'target':>7s}")
    for label, case, _ in CASES[:2]:
        initial_env, tree = case()
        assert isinstance(initial_env.env, str)
        make_raw = partial(gym.make, initial_env.env)
        make_built = partial(sg.make_env, initial_env, tree)
        raw_rates, built_rates = [], []
        for _ in range(rounds):
            raw_rates.append(ppo_throughput(make_raw, steps, {}))
            built_rates.append(ppo_throughput(make_built, steps, {}))
        raw_rate, built_rate = statistics.median(raw_rates), statistics.median(built_rates)
        ratio = built_rate / raw_rate
        print(
            f"{label:28s} {raw_rate:12.0f} {built_rate:14.0f} {ratio:7.3f} >= 0.9{' ok' if ratio >= 0.9 else ' MISSED'}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--ppo-steps", type=int, default=8192)
    parser.add_argument("--ppo-rounds", type=int, default=3)
    parser.add_argument("--skip-ppo", action="store_true")
    parser.add_argument("--n-envs", type=int, default=16, help="training's envs stepped together (0: skip)")
    parser.add_argument("--case", action="append", help="only the step cases whose label contains this (repeatable)")
    args = parser.parse_args()
    np.random.seed(0)
    bench_steps(args.steps, args.rounds, args.case)
    if args.n_envs:
        bench_batched(args.n_envs, args.steps, args.rounds, args.case)
    if not args.skip_ppo:
        bench_ppo(args.ppo_steps, args.ppo_rounds)


if __name__ == "__main__":
    main()
