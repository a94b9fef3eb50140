"""What the regression gate can see, by simulation: false alarms, power, seeds spent, in one run.

Simulates pull requests against a saved baseline with the gate itself
(:func:`specguard.stats.power.simulate_gate`: the permutation test per look, the
group-sequential levels, the stopping rule) and a session's family of
comparisons with Holm's procedure (:mod:`specguard.stats.family`). Per-seed true
success rates are beta-distributed around a goal's success with a seed-to-seed
spread; each seed is evaluated on 30 episodes, as at CI defaults. Two kinds of
goal, from the main job's figures:

* ``A``: about 93% success, spread 0.05 (Pendulum, CartPole, Acrobot, MountainCar);
* ``B``: about 42% success, spread 0.15 (LunarLander).

At CI defaults a baseline saved with ``--goal-specs-save`` stores
``DEFAULT_COMPARE_SEEDS`` (8) seeds per spec and a pull request starts with
the spec's 2, training 2 more at a time while a comparison is open, up to 8.

Prints: (1) flagged shares and seeds spent per kind of goal and true drop, in
a family of 15 comparisons under Holm; (2) family-wise false alarms over 15
unchanged goals; (3) per-comparison false alarms against the level, for the
gate's permutation test and, for contrast, a pooled t-test on the same
transformed rates (why the gate uses the former); (4) what larger budgets buy
on kind B; (5) what the extra seeds cost on the main job's specs, from its
measured training times; then one summary line with the targets. Exits 0
whatever the figures.

Usage:
    python benchmarks/bench_gate.py [--sims 2000]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from specguard.stats.family import first_level, holm_rejections
from specguard.stats.power import SeedLaw, Simulated, min_detectable_drop, simulate_gate
from specguard.stats.sequential import DEFAULT_ALPHA, DEFAULT_COMPARE_SEEDS, Design

EPISODES = 30
FAMILY = 15
START = 2
KINDS = {"A": SeedLaw(0.93, 0.05), "B": SeedLaw(0.42, 0.15)}
LABELS = {"A": "~93% success, spread 0.05 (Pendulum, CartPole)", "B": "~42% success, spread 0.15 (LunarLander)"}
# The main job's specs: kind, and training seconds for both seeds (docs/guide/case-studies.md, "The main job":
# measured on the 2-core CI machine with nothing else running, early stopped).
MAIN_JOB = {
    "Pendulum (a)": ("A", 42),
    "Pendulum (w)": ("A", 23),
    "Pendulum baseline": ("A", 21),
    "Acrobot (c)": ("A", 9),
    "Acrobot baseline": ("A", 11),
    "MountainCar (c+)": ("A", 10),
    "MountainCar baseline": ("A", 29),
    "LunarLander (w)": ("B", 214),
    "LunarLander (auto)": ("B", 383),
    "CartPole lean and catch": ("A", 10),
}
MIX = ["A"] * 13 + ["B"] * 2  # a session of 15 comparisons like the main job's: 13 of kind A, 2 of kind B


def design(baseline: int = DEFAULT_COMPARE_SEEDS, ceiling: int = DEFAULT_COMPARE_SEEDS) -> Design:
    return Design(alpha=first_level(DEFAULT_ALPHA, FAMILY), baseline_seeds=baseline, first=START, ceiling=ceiling)


def simulate(law: SeedLaw, drop: float, d: Design, sims: int, rng: np.random.Generator, **kw: object) -> Simulated:
    after = SeedLaw(max(law.success - drop, 0.0), law.spread)
    return simulate_gate(law, after, d, sims=sims, episodes=EPISODES, rng=rng, **kw)  # type: ignore[arg-type]


def family(kinds: list[str], drops: dict[int, float], d: Design, sims: int, rng: np.random.Generator):
    """Simulate sessions of ``len(kinds)`` comparisons (comparison i of kind kinds[i], true drop drops.get(i, 0))."""
    runs = [simulate(KINDS[k], drops.get(i, 0.0), d, sims, rng) for i, k in enumerate(kinds)]
    p = np.stack([r.p_drop for r in runs], axis=-1)
    return holm_rejections(p, DEFAULT_ALPHA), np.stack([r.seeds for r in runs], axis=-1)


def pooled_t(before: np.ndarray, after: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For contrast only: a one-sided pooled t-test on the transformed rates, variance floored at 30 episodes'."""
    from scipy.special import stdtr

    mb, ma = before.shape[-1], after.shape[-1]
    df = mb + ma - 2
    ss = ((before - before.mean(-1, keepdims=True)) ** 2).sum(-1) + ((after - after.mean(-1, keepdims=True)) ** 2).sum(
        -1
    )
    variance = np.maximum(ss / df, 1.0 / (4 * EPISODES + 2))
    t = (before.mean(-1) - after.mean(-1)) / np.sqrt(variance * (1 / mb + 1 / ma))
    return 1.0 - stdtr(df, t), stdtr(df, t)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sims", type=int, default=2000, help="simulated pull requests per row (default 2000)")
    args = parser.parse_args()
    sims = args.sims
    rng = np.random.default_rng(2024)
    start = time.perf_counter()
    d = design()
    print(
        f"gate: baseline {d.baseline_seeds} seeds, pull request {START} to start, +{d.step} per look up to "
        f"{d.ceiling} (looks at {', '.join(map(str, d.looks))}); permutation test per look, level spent "
        f"alpha * t^3; Holm over {FAMILY} comparisons at {DEFAULT_ALPHA:.0%} (each designed at {d.alpha:.2g}); "
        f"{EPISODES} episodes per seed; {sims} simulated pull requests per row"
    )

    print("\n(1) one goal's true drop, in a session of 15 comparisons (the other 14 unchanged, of the same kind)")
    print(f"{'goal like':<50} {'true drop':>9} {'flagged':>8} {'mean seeds':>10}  seeds at the end (2/4/6/8)")
    flagged: dict[tuple[str, float], float] = {}
    seeds_h0: dict[str, float] = {}
    for kind in KINDS:
        for drop in (0.0, 0.1, 0.2, 0.3):
            rejected, seeds = family([kind] * FAMILY, {0: drop}, d, sims, rng)
            share = float(rejected[:, 0].mean())
            flagged[(kind, drop)] = share
            if drop == 0.0:
                seeds_h0[kind] = float(seeds.mean())
            ends = np.bincount(seeds[:, 0], minlength=d.ceiling + 1)[list(d.looks)] / sims
            print(
                f"{LABELS[kind]:<50} {'none' if not drop else f'{drop * 100:.0f} points':>9} {share:>8.1%} "
                f"{seeds[:, 0].mean():>10.2f}  {' / '.join(f'{x:.0%}' for x in ends)}"
            )

    print("\n(2) family-wise false alarms: 15 comparisons, nothing changed (Holm at 5%)")
    fwer: dict[str, float] = {}
    for name, kinds in {
        "all kind A": ["A"] * FAMILY,
        "all kind B": ["B"] * FAMILY,
        "main-job mix (13 A, 2 B)": MIX,
    }.items():
        rejected, seeds = family(kinds, {}, d, sims, rng)
        fwer[name] = float(rejected.any(-1).mean())
        print(f"{name:<28} any flagged in {fwer[name]:6.2%} of sessions; mean seeds per spec {seeds.mean():.2f}")
    mix_seeds = float(np.mean([seeds_h0[k] for k in MIX]))

    print(f"\n(3) one comparison, nothing changed: false alarms at its level {d.alpha:.2g}, as a multiple of it")
    print(f"{'seeds of one comparison':<38} {'permutation (gate)':>18} {'pooled t (contrast)':>20}")
    grid_sims = sims * 5
    worst = 0.0
    for success, spread in [
        (0.42, 0.15),
        (0.5, 0.25),
        (0.8, 0.15),
        (0.8, 0.25),
        (0.93, 0.05),
        (0.93, 0.15),
        (0.97, 0.05),
    ]:
        law = SeedLaw(success, spread)
        ratios = []
        for test in ("permutation", "t"):
            extra = {} if test == "permutation" else {"test": pooled_t}
            result = simulate(law, 0.0, d, grid_sims, rng, **extra)
            ratios.append(float((result.p_drop <= d.alpha).mean()) / d.alpha)
        worst = max(worst, ratios[0])
        print(f"success {success:.2f}, spread {spread:.2f}{'':<12} {ratios[0]:>18.2f} {ratios[1]:>20.2f}")

    print("\n(4) kind B (LunarLander-like): a 20-point drop, flagged in a session of 15, by budget")
    for baseline, ceiling in [(8, 8), (16, 8), (16, 12), (24, 12)]:
        db = design(baseline, ceiling)
        rejected, seeds = family(["B"] * FAMILY, {0: 0.2}, db, sims, rng)
        _, seeds0 = family(["B"], {}, db, sims, rng)
        print(
            f"baseline {baseline:>2} seeds, pull request up to {ceiling:>2}: flagged {rejected[:, 0].mean():6.1%}; "
            f"mean seeds {seeds[:, 0].mean():.1f} (dropped), {seeds0.mean():.1f} (nothing changed)"
        )

    print("\n(5) the cost on the main job's specs (s per seed: the main job's table, docs/guide/case-studies.md)")
    print(f"{'spec':<26} {'s per seed':>10} {'save: +6 seeds':>14} {'PR, spec changed, no drop':>26}")
    save_total = pr_total = 0.0
    for spec, (kind, both) in MAIN_JOB.items():
        per_seed = both / 2
        save = per_seed * (d.baseline_seeds - START)
        pr = per_seed * (seeds_h0[kind] - START)
        save_total += save
        pr_total += pr
        print(f"{spec:<26} {per_seed:>10.0f} {save:>13.0f}s {pr:>25.0f}s")
    print(
        f"{'all':<26} {'':>10} {save_total:>13.0f}s {pr_total:>25.0f}s  (a spec whose identity is unchanged "
        "reuses the baseline's runs: 0 s)"
    )

    print("\nplan's smallest drop flagged with 80% power (specguard plan), for the same designs:")
    for kind, law in KINDS.items():
        at_start = min_detectable_drop(law.success, law.spread, replace(d, ceiling=START), episodes=EPISODES)
        extra = min_detectable_drop(law.success, law.spread, d, episodes=EPISODES)
        text = [("none" if x is None else f"{x * 100:.0f} points") for x in (at_start, extra)]
        print(f"kind {kind}: with {START} seeds only: {text[0]}; with up to {d.ceiling}: {text[1]}")

    a20, b20 = flagged[("A", 0.2)], flagged[("B", 0.2)]
    worst_fwer = max(fwer.values())
    checks = [
        ("A 20-pt drop flagged", a20, a20 >= 0.8, ">= 80%"),
        ("B 20-pt drop flagged", b20, b20 >= 0.6, ">= 60%"),
        ("family-wise false alarms", worst_fwer, worst_fwer <= 0.05, "<= 5%"),
    ]
    parts = [f"{name} {value:.1%} ({target}: {'met' if ok else 'MISSED'})" for name, value, ok, target in checks]
    verdicts = ["met" if x <= 3 else "MISSED" for x in (mix_seeds, seeds_h0["B"])]
    parts.append(
        f"mean seeds per spec, nothing changed: mix {mix_seeds:.2f}, A {seeds_h0['A']:.2f}, B {seeds_h0['B']:.2f} "
        f"(<= 3: {verdicts[0]} for the mix, {verdicts[1]} for B)"
    )
    parts.append(f"worst per-comparison false-alarm ratio {worst:.2f}")
    print(f"\n({time.perf_counter() - start:.0f} s)")
    print("SUMMARY: " + "; ".join(parts))
    return 0


if __name__ == "__main__":
    sys.exit(main())
