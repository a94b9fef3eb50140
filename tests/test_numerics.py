"""Portable numerics (specguard/utils/numerics.py): a run's weights do not follow the kernels the machine would
pick, a native run's do, and a process that cannot hold them is refused."""

from __future__ import annotations

import pytest

import specguard as sg
from specguard.cache.fingerprint import fingerprint_spec
from specguard.cache.versions import torch_capability
from specguard.error import InvalidSpec, NumericsError
from specguard.training.result import RunResult
from specguard.utils import numerics
from specguard.utils.numerics import LIBM, PORTABLE, hold_numerics, numerics_environ, numerics_key, with_libm

SPEC_FILE = """
import specguard as sg

balance = sg.Spec(
    sg.InitialEnv("CartPole-v1", features=("x", "v", "theta", "omega")),
    sg.Always(sg.Goal("upright", theta=(-0.2, 0.2)), name="balance"),
    expect=0.5,
    budget=sg.Budget(timesteps=1024, eval_episodes=2, max_eval_episodes=2, min_seeds=1, max_seeds=1, checkpoints=1),
    trainer=sg.SB3(hyperparameters={"n_steps": 256, "batch_size": 64, "n_epochs": 2}),
)
"""
_FILE: dict = {}
exec(SPEC_FILE, _FILE)  # the spec the command line reads, as Python's doors take it


def _spec(numerics: str = "portable") -> sg.Spec:
    return _FILE["balance"].as_run(numerics=numerics)


def _trained(numerics: str) -> RunResult:
    result = sg.run_spec(_spec(numerics), workers=1, cache_dir=None, progress=None)
    assert not result.errors, result.errors
    return result.runs[0]


# -- the settings ------------------------------------------------------------------------------------------------


def test_portable_numerics_are_four_settings_and_native_none():
    assert numerics_environ("portable") == {
        "ATEN_CPU_CAPABILITY": "default",
        "MKL_CBWR": "COMPATIBLE",
        "ONEDNN_MAX_CPU_ISA": "SSE41",
    }
    assert numerics_environ("native") == {}
    assert with_libm({})["GLIBC_TUNABLES"] == LIBM == "glibc.cpu.hwcaps=-AVX2,-AVX512F,-FMA,-AVX"
    kept = with_libm({"GLIBC_TUNABLES": f"glibc.malloc.check=0:{LIBM}"})
    assert kept["GLIBC_TUNABLES"] == f"glibc.malloc.check=0:{LIBM}"  # held once, the user's kept


def test_a_native_key_names_this_cpu_and_a_portable_one_does_not():
    import torch

    assert numerics_key("portable", torch_capability) == "portable"
    assert numerics_key("native", torch_capability).startswith(f"native: {torch.backends.cpu.get_cpu_capability()}, ")
    portable, native = fingerprint_spec(_spec("portable")), fingerprint_spec(_spec("native"))
    assert portable.run_key(0) != native.run_key(0) and portable.spec_key != native.spec_key


def test_numerics_is_one_of_its_choices_at_the_spec_and_as_run():
    with pytest.raises(InvalidSpec, match=r"expected numerics to be one of portable, native, got 'fast'"):
        _spec("fast")
    assert _spec().numerics == "portable" and _spec().as_run(numerics="native").numerics == "native"
    with pytest.raises(InvalidSpec, match=r"expected numerics to be one of portable, native, got 'x'"):
        _spec().as_run(numerics="x")


# -- a process that cannot hold them is refused ----------------------------------------------------------------


def test_a_process_started_without_the_settings_is_refused_naming_each(monkeypatch):
    for key in PORTABLE:
        monkeypatch.delenv(key, raising=False)
    monkeypatch.setattr(numerics, "_STARTED", {"GLIBC_TUNABLES": "glibc.malloc.check=0"})
    with pytest.raises(NumericsError) as info:
        hold_numerics("portable", "Spec 'x', seed 0", torch_capability)
    message = info.value.message
    assert message.startswith("Spec 'x', seed 0: portable numerics need ATEN_CPU_CAPABILITY=default MKL_CBWR=")
    assert f"GLIBC_TUNABLES={LIBM}" in message and "GLIBC_TUNABLES='glibc.malloc.check=0'" in message
    assert "dask worker" in info.value.hint and "numerics='native'" in info.value.hint


def test_a_process_whose_torch_chose_its_kernels_first_is_refused(monkeypatch):
    import torch

    monkeypatch.setattr(numerics, "_STARTED", {"GLIBC_TUNABLES": LIBM})
    for key, value in PORTABLE.items():
        monkeypatch.setenv(key, value)  # too late for this process: its torch has chosen already
    chosen = torch.backends.cpu.get_cpu_capability()
    if chosen == "DEFAULT":
        pytest.skip("this process's torch runs its DEFAULT kernels already")
    with pytest.raises(NumericsError, match=rf"need torch's DEFAULT kernels, and this process's torch chose {chosen}"):
        hold_numerics("portable", "here", torch_capability)
    assert hold_numerics("native", "here", torch_capability) == f"native ({chosen})"


# -- the weights -------------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_portable_weights_do_not_follow_the_kernels_the_machine_would_pick_and_native_ones_do(monkeypatch):
    # Another CPU, as far as one machine can show it: the parent's environment picks torch's AVX2 kernels, then its
    # DEFAULT ones (and MKL's AVX2 branch), as CPUs with and without AVX2 would pick them.
    import torch

    if torch.backends.cpu.get_cpu_capability() not in ("AVX2", "AVX512"):
        pytest.skip("needs a CPU with AVX2, whose kernels differ from DEFAULT's")
    for key in PORTABLE:
        monkeypatch.delenv(key, raising=False)
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "avx2")
    avx2 = {"portable": _trained("portable"), "native": _trained("native")}
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "default")
    monkeypatch.setenv("MKL_CBWR", "AVX2")
    default = {"portable": _trained("portable"), "native": _trained("native")}
    assert avx2["portable"].numerics == default["portable"].numerics == "portable"
    assert (avx2["native"].numerics, default["native"].numerics) == ("native (AVX2)", "native (DEFAULT)")
    assert avx2["portable"].weights_digest == default["portable"].weights_digest  # the promise
    assert avx2["native"].weights_digest != default["native"].weights_digest  # what it holds against
    assert avx2["portable"].weights_digest != avx2["native"].weights_digest


@pytest.mark.slow
def test_the_command_line_gives_the_same_digest_whatever_kernels_its_environment_picks(monkeypatch, tmp_path):
    import json

    from specguard.cli.main import main

    spec_file = tmp_path / "specs.py"
    spec_file.write_text(SPEC_FILE)
    digests = {}
    for capability in ("avx2", "default"):
        monkeypatch.setenv("ATEN_CPU_CAPABILITY", capability)
        out = tmp_path / f"{capability}.json"
        main(["run", str(spec_file), "--no-cache", "--quiet", "--json", str(out)])
        (result,) = json.loads(out.read_text()).values()
        digests[capability] = [(run["numerics"], run["weights_digest"]) for run in result["runs"]]
    assert digests["avx2"] == digests["default"] and digests["avx2"][0][0] == "portable"
