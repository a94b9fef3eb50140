"""Which CPU-dispatch settings change the bits, measured in one run: the envs alone, and small policy nets.

The same spec and seed can train different weights when only the CPU's vector kernels change (issue "Portable
verdicts"). Each library picks its kernels at load time from the CPU it finds, and each has its own switch to
pin that choice; this measures, on this machine, which switch changes which digest. Every case runs in a fresh
interpreter (``--child``) whose environment is set before NumPy, torch or glibc's libm are loaded, one torch,
MKL and OpenMP thread.

1. **Envs alone.** For every case-study spec of ``example_specs`` that imports here, its initial env
   (``spec.initial_env.make()``) steps ``--steps`` times with actions from ``env.action_space.seed(0)`` /
   ``sample()``, reset with seeds 0, 1, 2, ... at each episode's end; the sha256 of every observation, reward and
   end flag, as bytes. Beside them two probes: NumPy's ufuncs and reductions (``exp``, ``sin``, ``log``, ``tanh``,
   ``sum``, ``var`` on fixed float32/float64 arrays) and glibc's libm through ``math`` (``exp``, ``log``, ``sin``,
   ``cos``, ``pow``, ``atan``: the functions glibc picks an FMA/AVX2 variant of by ifunc). Settings: native;
   ``NPY_DISABLE_CPU_FEATURES`` as first written for the issue (feature names that NumPy 2.4 no longer
   dispatches on, so it warns, with an ``ImportWarning`` that is hidden by default, and keeps them) and as NumPy's
   own dispatch targets (``numpy._core._multiarray_umath.__cpu_dispatch__``, read from this interpreter); the
   ``glibc.cpu.hwcaps`` tunable with the ``*_Usable`` names of glibc < 2.33 (ignored, silently, by newer glibc)
   and with the names glibc >= 2.33 reads; NumPy's and glibc's working settings together. The child reports what
   NumPy runs ``exp`` on (``numpy.lib.introspect.opt_func_info``) so a setting that did not take shows.
2. **Policy nets.** ``--net-steps`` SGD steps (forward, cross-entropy, backward) from ``torch.manual_seed(0)`` on
   a fixed random batch, sha256 of the weights after: SB3's ``NatureCNN`` on 3x56x56 images (the
   ``minigrid_image`` spec's observation), a three-layer 2x2 conv stack on 3x7x7 (MiniGrid's symbolic view), and
   SB3's default 64x64 tanh MLP on 4 features. Settings: native; ``ATEN_CPU_CAPABILITY=default`` with
   ``MKL_CBWR=COMPATIBLE``; that with ``ONEDNN_MAX_CPU_ISA=SSE41``; that pair with
   ``torch.backends.mkldnn.enabled = False`` instead. Then one step of ``NatureCNN`` under ``ONEDNN_VERBOSE=1``,
   native and with ``ONEDNN_MAX_CPU_ISA=SSE41``, to show which oneDNN kernels ran and on what ISA.

3. **SB3 PPO** (only with ``--ppo-steps N``): ``MlpPolicy`` on CartPole-v1 and Pendulum-v1, seed 0, for ``N``
   steps; the weights' digest under native, ``ATEN_CPU_CAPABILITY=default`` + ``MKL_CBWR=COMPATIBLE``, and that
   with NumPy's dispatch targets off or glibc's FMA/AVX variants off (whether the env's and SB3's own NumPy
   arithmetic reaches the weights once torch is pinned).

Each table has a ``native again`` row (a second fresh interpreter, no setting) first: a digest that differs
there is not deterministic on this machine and says nothing about the settings. The time columns are one run's
seconds (the rollouts, the SGD steps; not the imports) and their ratio to the native run's: the cost of each
setting, noisy on a shared machine.

Prints the figures; exits 0 whatever they are. A setting that leaves a digest unchanged on this machine only
says that the code it pins was not what differed here; a second CPU is the test of portability.

Usage:
    python benchmarks/bench_numerics.py [--steps 2000] [--net-steps 20] [--skip-envs] [--skip-nets] [--ppo-steps 4096]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
MARK = "BENCH_NUMERICS "
"""The child's result line starts with this (oneDNN's verbose lines go to the same stdout)."""

ENV_MODULES = (
    "pendulum",
    "cartpole",
    "acrobot",
    "mountain_car",
    "lunar_lander",
    "inverted_pendulum",
    "minigrid_empty",
    "minigrid_image",
    "highway",
)
NETS = ("nature_cnn", "conv_7x7", "mlp")
THREADS = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}

NPY_AS_WRITTEN = "AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR AVX2 FMA3 AVX F16C"
GLIBC_OLD_NAMES = "glibc.cpu.hwcaps=-AVX2_Usable,-AVX512F_Usable,-FMA_Usable,-AVX_Usable"
GLIBC_NAMES = "glibc.cpu.hwcaps=-AVX2,-AVX512F,-FMA,-AVX"
TORCH_PINNED = {"ATEN_CPU_CAPABILITY": "default", "MKL_CBWR": "COMPATIBLE"}


def _numpy_dispatch() -> str:
    """NumPy's own dispatch targets on this build (``X86_V3 X86_V4 ...`` on NumPy 2.4): what can be disabled."""
    from numpy._core._multiarray_umath import __cpu_dispatch__

    return " ".join(__cpu_dispatch__)


def _env_settings() -> list[tuple[str, dict[str, str]]]:
    dispatch = _numpy_dispatch()
    return [
        ("native", {}),
        ("native again", {}),
        ("numpy: names as written", {"NPY_DISABLE_CPU_FEATURES": NPY_AS_WRITTEN}),
        ("numpy: its dispatch targets", {"NPY_DISABLE_CPU_FEATURES": dispatch}),
        ("glibc: *_Usable names", {"GLIBC_TUNABLES": GLIBC_OLD_NAMES}),
        ("glibc: -AVX2,-AVX512F,-FMA,-AVX", {"GLIBC_TUNABLES": GLIBC_NAMES}),
        ("numpy + glibc", {"NPY_DISABLE_CPU_FEATURES": dispatch, "GLIBC_TUNABLES": GLIBC_NAMES}),
    ]


NET_SETTINGS: list[tuple[str, dict[str, str], bool]] = [
    ("native", {}, True),
    ("native again", {}, True),
    ("aten default + MKL_CBWR=COMPATIBLE", TORCH_PINNED, True),
    ("that + ONEDNN_MAX_CPU_ISA=SSE41", {**TORCH_PINNED, "ONEDNN_MAX_CPU_ISA": "SSE41"}, True),
    ("aten default + CBWR + mkldnn off", TORCH_PINNED, False),
]

PPO_ENVS = ("CartPole-v1", "Pendulum-v1")


def _ppo_settings(dispatch: str) -> list[tuple[str, dict[str, str]]]:
    """native, torch pinned, and torch pinned with NumPy's dispatch and glibc's FMA/AVX variants off."""
    return [
        ("native", {}),
        ("native again", {}),
        ("aten default + MKL_CBWR=COMPATIBLE", TORCH_PINNED),
        ("that + numpy dispatch off", {**TORCH_PINNED, "NPY_DISABLE_CPU_FEATURES": dispatch}),
        ("that + glibc -AVX2,-AVX512F,-FMA,-AVX", {**TORCH_PINNED, "GLIBC_TUNABLES": GLIBC_NAMES}),
    ]


# -- the children --------------------------------------------------------------------------------------------


def _sha(chunks: list[bytes]) -> str:
    h = hashlib.sha256()
    for chunk in chunks:
        h.update(chunk)
    return h.hexdigest()[:12]


def _obs_bytes(obs: Any) -> bytes:
    import numpy as np

    if isinstance(obs, dict):
        return b"".join(k.encode() + _obs_bytes(obs[k]) for k in sorted(obs))
    if isinstance(obs, str):
        return obs.encode()
    return np.ascontiguousarray(obs).tobytes()


def _probes() -> dict[str, str]:
    """Digests of NumPy's vector ufuncs and reductions, and of glibc's libm through ``math``, on fixed inputs."""
    import math

    import numpy as np

    rng = np.random.default_rng(0)
    out = {}
    chunks = []
    for dtype in (np.float32, np.float64):
        x = rng.uniform(-10.0, 10.0, 100_003).astype(dtype)
        for fn in (np.exp, np.sin, np.cos, np.tanh):
            chunks.append(fn(x).tobytes())
        chunks.append(np.log(np.abs(x) + 1).tobytes())
        chunks.append(np.asarray([x.sum(), x.var(), np.dot(x, x)], dtype=dtype).tobytes())
    out["numpy"] = _sha(chunks)
    xs = [i * 0.001 - 50.0 for i in range(100_000)]
    libm = []
    for fn in (math.exp, math.sin, math.cos, math.atan, math.tan):
        libm.append(np.asarray([fn(v) for v in xs]).tobytes())
    libm.append(np.asarray([math.log(abs(v) + 1e-3) for v in xs]).tobytes())
    libm.append(np.asarray([math.pow(abs(v) + 0.5, 1.37) for v in xs]).tobytes())
    out["libm"] = _sha(libm)
    from numpy.lib import introspect

    info = introspect.opt_func_info(func_name="^exp$", signature="float64")
    out["numpy exp on"] = next(iter(info["exp"].values()))["current"]
    return out


def _rollout(module_name: str, steps: int) -> dict[str, Any]:
    import importlib

    try:
        module = importlib.import_module(f"example_specs.{module_name}")
    except ImportError as e:
        return {"skipped": f"{type(e).__name__}: {e}"}
    spec = next(iter(module.specs.values()))
    env = spec.initial_env.make()
    env.action_space.seed(0)
    start = time.perf_counter()
    episode = 0
    obs, _ = env.reset(seed=episode)
    chunks = [_obs_bytes(obs)]
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
        chunks += [_obs_bytes(obs), float(reward).hex().encode(), bytes([terminated, truncated])]
        if terminated or truncated:
            episode += 1
            obs, _ = env.reset(seed=episode)
            chunks.append(_obs_bytes(obs))
    seconds = time.perf_counter() - start
    env.close()
    return {"digest": _sha(chunks), "seconds": seconds, "episodes": episode}


def _net(name: str) -> tuple[Any, Any, int]:
    """The net, its input batch and its number of classes, all from ``torch.manual_seed(0)``."""
    import torch
    from torch import nn

    torch.manual_seed(0)
    if name == "nature_cnn":
        import gymnasium as gym
        import numpy as np
        from stable_baselines3.common.torch_layers import NatureCNN

        space = gym.spaces.Box(0, 255, (3, 56, 56), np.uint8)
        net = nn.Sequential(NatureCNN(space, features_dim=512), nn.ReLU(), nn.Linear(512, 7))
        x = torch.randint(0, 256, (32, 3, 56, 56)).float() / 255.0
        return net, x, 7
    if name == "conv_7x7":
        net = nn.Sequential(
            nn.Conv2d(3, 16, 2), nn.ReLU(), nn.MaxPool2d(2),
            nn.Conv2d(16, 32, 2), nn.ReLU(), nn.Conv2d(32, 64, 2), nn.ReLU(),
            nn.Flatten(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, 7),
        )  # fmt: skip
        x = torch.randint(0, 11, (64, 3, 7, 7)).float() / 10.0
        return net, x, 7
    net = nn.Sequential(nn.Linear(4, 64), nn.Tanh(), nn.Linear(64, 64), nn.Tanh(), nn.Linear(64, 2))
    return net, torch.randn(64, 4), 2


def _train(name: str, steps: int) -> dict[str, Any]:
    import torch

    net, x, classes = _net(name)
    y = torch.randint(0, classes, (x.shape[0],), generator=torch.Generator().manual_seed(1))
    optimizer = torch.optim.SGD(net.parameters(), lr=0.05, momentum=0.9)
    start = time.perf_counter()
    for _ in range(steps):
        optimizer.zero_grad()
        torch.nn.functional.cross_entropy(net(x), y).backward()
        optimizer.step()
    seconds = time.perf_counter() - start
    weights = [p.detach().contiguous().numpy().tobytes() for p in net.state_dict().values()]
    return {"digest": _sha(weights), "seconds": seconds}


def _ppo(env_id: str, steps: int) -> dict[str, Any]:
    """SB3 PPO (``MlpPolicy``, seed 0, 512-step rollouts) for ``steps`` on ``env_id``; the digest of its weights."""
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", env_id, n_steps=512, batch_size=64, seed=0, device="cpu")
    start = time.perf_counter()
    model.learn(steps)
    seconds = time.perf_counter() - start
    weights = [p.detach().contiguous().numpy().tobytes() for p in model.policy.state_dict().values()]
    return {"digest": _sha(weights), "seconds": seconds}


def child(part: str, names: list[str], steps: int, mkldnn: bool) -> None:
    sys.path.insert(0, str(ROOT))
    result: dict[str, Any] = {}
    if part == "envs":
        result["probes"] = _probes()
        for name in names:
            result[name] = _rollout(name, steps)
    else:
        import torch

        torch.set_num_threads(1)
        torch.backends.mkldnn.enabled = mkldnn
        result["aten"] = torch.backends.cpu.get_cpu_capability()
        for name in names:
            result[name] = _ppo(name, steps) if part == "ppo" else _train(name, steps)
    print(MARK + json.dumps(result), flush=True)


# -- the parent ----------------------------------------------------------------------------------------------


def _run(
    part: str, names: list[str], steps: int, extra: dict[str, str], mkldnn: bool = True
) -> tuple[dict[str, Any], str]:
    env = {**os.environ, **THREADS, **extra}
    for var in ("NPY_DISABLE_CPU_FEATURES", "GLIBC_TUNABLES", "ATEN_CPU_CAPABILITY", "MKL_CBWR",
                "ONEDNN_MAX_CPU_ISA", "ONEDNN_VERBOSE"):  # fmt: skip
        if var not in extra:
            env.pop(var, None)
    command = [sys.executable, "-W", "always::ImportWarning", __file__, "--child", part,
               "--names", ",".join(names), "--steps", str(steps)] + ([] if mkldnn else ["--mkldnn-off"])  # fmt: skip
    done = subprocess.run(command, env=env, capture_output=True, text=True, cwd=ROOT)
    lines = [line for line in done.stdout.splitlines() if line.startswith(MARK)]
    if done.returncode or not lines:
        raise RuntimeError(f"child failed ({done.returncode}):\n{done.stdout[-2000:]}\n{done.stderr[-2000:]}")
    warned = " ".join(line.strip() for line in done.stderr.splitlines() if "cannot disable" in line)
    return {**json.loads(lines[-1][len(MARK) :]), "warned": warned}, done.stdout


def _table(title: str, names: list[str], rows: list[tuple[str, dict[str, Any]]], extra: list[str]) -> None:
    """One row per setting: each case's digest ('= native' where it matches) and its time ratio to native."""
    native = rows[0][1]
    print(f"\n{title}")
    width = max(len(label) for label, _ in rows)
    head = f"{'setting':<{width}} " + " ".join(f"{e:>16}" for e in extra)
    head += " " + " ".join(f"{n[:16]:>16}" for n in names)
    print(head)
    for label, result in rows:
        cells = [f"{result.get(e, result.get('probes', {}).get(e, ''))!s:>16}" for e in extra]
        for name in names:
            case, base = result[name], native[name]
            if "skipped" in case:
                cells.append(f"{'skipped':>16}")
                continue
            same = "=" if case["digest"] == base["digest"] and label != rows[0][0] else case["digest"][:8]
            ratio = case["seconds"] / base["seconds"] if base["seconds"] else float("nan")
            cells.append(f"{same:>9} {ratio:5.2f}x")
        print(f"{label:<{width}} " + " ".join(cells))
    print(f"{'native seconds':<{width}} " + " " * (17 * len(extra)) + " ".join(
        f"{'':>9} {native[n]['seconds']:5.2f}s" if "seconds" in native[n] else f"{'':>16}" for n in names))  # fmt: skip
    skipped = {n: native[n]["skipped"] for n in names if "skipped" in native[n]}
    for name, why in skipped.items():
        print(f"  {name}: skipped ({why})")


def _onednn_kernels(net: str, extra: dict[str, str], steps: int) -> list[str]:
    """The ISA line and the distinct (primitive, implementation) pairs oneDNN's verbose mode shows for a net."""
    _, stdout = _run("nets", [net], steps, {**extra, "ONEDNN_VERBOSE": "1"})
    isa = [
        line.split(",", 3)[-1] for line in stdout.splitlines() if line.startswith("onednn_verbose") and "isa:" in line
    ]
    seen: dict[str, int] = {}
    for line in stdout.splitlines():
        parts = line.split(",")
        if line.startswith("onednn_verbose") and "exec" in parts:
            at = parts.index("exec")
            key = f"{parts[at + 2]}:{parts[at + 3]}"  # exec,cpu,<primitive>,<implementation>
            seen[key] = seen.get(key, 0) + 1
    if not seen:
        return ["no oneDNN primitive ran"]
    return isa[:1] + [f"{k} x{v}" for k, v in sorted(seen.items())]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="env steps per rollout (envs) or SGD steps (child)")
    parser.add_argument("--net-steps", type=int, default=20)
    parser.add_argument("--skip-envs", action="store_true")
    parser.add_argument("--skip-nets", action="store_true")
    parser.add_argument("--ppo-steps", type=int, default=0, help="also train SB3 PPO this long (0: skip)")
    parser.add_argument("--child", choices=("envs", "nets", "ppo"), help=argparse.SUPPRESS)
    parser.add_argument("--names", default="", help=argparse.SUPPRESS)
    parser.add_argument("--mkldnn-off", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child, [n for n in args.names.split(",") if n], args.steps, not args.mkldnn_off)
        return
    import numpy as np

    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, NumPy dispatch targets: {_numpy_dispatch()}")
    if not args.skip_envs:
        rows = []
        for label, extra in _env_settings():
            result, _ = _run("envs", list(ENV_MODULES), args.steps, extra)
            rows.append((label, result))
            if result["warned"]:
                print(f"  [{label}] NumPy warned: {result['warned'][:400]}")
        _table(
            f"Envs alone: {args.steps} random steps each (digest, or '=' where it is native's; time / native's)",
            list(ENV_MODULES), rows, ["numpy exp on", "numpy", "libm"],
        )  # fmt: skip
    if not args.skip_nets:
        rows = []
        for label, extra, mkldnn in NET_SETTINGS:
            rows.append((label, _run("nets", list(NETS), args.net_steps, extra, mkldnn)[0]))
        _table(f"Policy nets: {args.net_steps} SGD steps each, one thread", list(NETS), rows, ["aten"])
        print("\noneDNN verbose (ONEDNN_VERBOSE=1), 1 SGD step, under aten default + MKL_CBWR=COMPATIBLE:")
        for net in NETS:
            for label, extra in (("", {}), (" + ONEDNN_MAX_CPU_ISA=SSE41", {"ONEDNN_MAX_CPU_ISA": "SSE41"})):
                print(f"  {net}{label}:")
                for line in _onednn_kernels(net, {**TORCH_PINNED, **extra}, 1):
                    print(f"    {line}")

    if args.ppo_steps:
        dispatch = _numpy_dispatch()
        rows = []
        for label, extra in _ppo_settings(dispatch):
            rows.append((label, _run("ppo", list(PPO_ENVS), args.ppo_steps, extra)[0]))
        _table(f"SB3 PPO MlpPolicy, {args.ppo_steps} steps, seed 0, one thread", list(PPO_ENVS), rows, ["aten"])


if __name__ == "__main__":
    main()
