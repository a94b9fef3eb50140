"""Portable numerics: the kernels a process that trains or judges computes with, held to those every x86-64 CPU
computes alike.

torch picks its vectorized CPU kernels (ATen's ``DEFAULT``, ``AVX2``, ``AVX512``), Intel MKL its matrix kernels,
oneDNN its convolution kernels and glibc's libm its ``sin``, ``cos``, ``exp`` and ``pow`` (FMA or not) by the CPU
they run on, once, when they are first used; they round differently, so the same spec and seed trained different
weights on an AVX-512 Xeon and an AVX2 EPYC, and a verdict followed the machine. Measured on one machine (each
setting in a fresh process; docs/guide/numerics.md has the tables):

* SB3 PPO (an MLP), 4,096 steps: ATen's ``AVX512`` and ``AVX2`` kernels gave one digest of the weights and
  ``DEFAULT`` another; MKL's ``AUTO``, ``AVX2``, ``SSE4_2`` and ``COMPATIBLE`` branches four;
* a convolution net: oneDNN ran its AVX-512 kernels beside the two settings above, and its SSE4.1 ones with
  ``ONEDNN_MAX_CPU_ISA=SSE41``;
* the envs: libm's FMA variants changed Pendulum's, Acrobot's and InvertedPendulum's (MuJoCo's) rollouts;
  NumPy's dispatched CPU features changed no env, nor the MLP's weights.

So four settings are held (:data:`PORTABLE` and :data:`LIBM`), and not NumPy's:

* ``ATEN_CPU_CAPABILITY=default``: torch's kernels without vector extensions;
* ``MKL_CBWR=COMPATIBLE``: MKL's conditional numerical reproducibility, its one code path for every CPU;
* ``ONEDNN_MAX_CPU_ISA=SSE41``: oneDNN's convolutions on the instructions every x86-64 CPU has (a CNN policy
  trains about 3x slower; an MLP runs no oneDNN kernel);
* ``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-AVX512F,-FMA,-AVX``: libm's variants without FMA, which every x86-64
  CPU computes alike.

The first three are read when the library first computes, so a worker gets them in its environment before it
starts (:func:`numerics_environ`); glibc's is read when a process starts, so specguard's fork server and spawned
workers start with it (:func:`with_libm`: it costs nothing measurable, and holds native runs' libm too). A worker
checks them before it trains (:func:`hold_numerics`): a process that started without them, or whose torch already
chose other kernels (a long-lived cluster worker started without them), is refused, never trained in silence.
``numerics="native"``
leaves torch, MKL and oneDNN to choose, for native speed and machine-dependent results; its cache key names the
CPU (:func:`numerics_key`), so a native run from another CPU is not taken for this one's.

The promise is "the same versions on any x86-64 CPU": another torch, NumPy, SB3 or glibc version, or an ARM CPU,
is another platform.

Example:
    >>> sorted(numerics_environ("portable"))
    ['ATEN_CPU_CAPABILITY', 'MKL_CBWR', 'ONEDNN_MAX_CPU_ISA']
    >>> with_libm({"GLIBC_TUNABLES": "glibc.malloc.check=0"})["GLIBC_TUNABLES"]
    'glibc.malloc.check=0:glibc.cpu.hwcaps=-AVX2,-AVX512F,-FMA,-AVX'
    >>> numerics_environ("native"), numerics_key("portable", lambda: "AVX512")
    ({}, 'portable')
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Mapping

from specguard.error import NumericsError

__all__ = [
    "LIBM",
    "NUMERICS",
    "PORTABLE",
    "cpu_model",
    "hold_numerics",
    "numerics_environ",
    "numerics_key",
    "portable_environ",
    "started_with",
    "with_libm",
]

NUMERICS = ("portable", "native")
"""What a run computes with: ``"portable"`` (the default: :data:`PORTABLE`), or ``"native"`` (the libraries' own
choice for this CPU)."""

LIBM = "glibc.cpu.hwcaps=-AVX2,-AVX512F,-FMA,-AVX"
"""glibc's tunable that keeps libm's variants to those without FMA (read when a process starts)."""

PORTABLE: Mapping[str, str] = {
    "ATEN_CPU_CAPABILITY": "default",
    "MKL_CBWR": "COMPATIBLE",
    "ONEDNN_MAX_CPU_ISA": "SSE41",
}
"""The environment that holds torch's, MKL's and oneDNN's kernels to those every x86-64 CPU computes alike (read
when each library first computes: a worker gets them before it starts its task); libm's is :data:`LIBM`."""

_STARTED: dict[str, str] | None = None  # the environment this process started with, where a worker recorded it


def started_with(environ: Mapping[str, str]) -> None:
    """Record the environment this process started with (a forked worker's is its fork server's: what glibc read),
    before it takes its parent's; :func:`hold_numerics` reads it."""
    global _STARTED
    _STARTED = dict(environ)


def with_libm(environ: Mapping[str, str]) -> dict[str, str]:
    """``environ`` with :data:`LIBM` among its ``GLIBC_TUNABLES`` (others kept), as a process must start with it."""
    said = environ.get("GLIBC_TUNABLES", "")
    if LIBM in said.split(":"):
        return dict(environ)
    return {**environ, "GLIBC_TUNABLES": f"{said}:{LIBM}" if said else LIBM}


def numerics_environ(numerics: str) -> dict[str, str]:
    """The environment variables a worker that computes with ``numerics`` starts with (none for native)."""
    return dict(PORTABLE) if numerics == "portable" else {}


def portable_environ(environ: Mapping[str, str]) -> dict[str, str]:
    """``environ`` with every portable setting, :data:`PORTABLE` and :data:`LIBM`: the environment to start a
    long-lived worker of one's own with (a Dask ``LocalCluster``'s, ``dask worker``'s), whose tasks specguard cannot
    set before they start.

    Example:
        >>> sorted(portable_environ({}))
        ['ATEN_CPU_CAPABILITY', 'GLIBC_TUNABLES', 'MKL_CBWR', 'ONEDNN_MAX_CPU_ISA']
    """
    return with_libm({**environ, **PORTABLE})


def _holds(environ: Mapping[str, str], key: str) -> bool:
    return environ.get(key, "").lower() == PORTABLE[key].lower()


def numerics_key(numerics: str, capability: Callable[[], str]) -> str:
    """What a run's cache key says of its numerics: ``"portable"``, or ``"native"`` with the vector kernels torch
    picks here (``capability()``, torch's ``get_cpu_capability``) and this CPU's model (a native run is this CPU's
    only)."""
    return "portable" if numerics == "portable" else f"native: {capability()}, {cpu_model()}"


@functools.cache
def cpu_model() -> str:
    """This CPU's model name, as Linux's ``/proc/cpuinfo`` says it (``"unknown CPU"`` where it cannot be read)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            return next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), "unknown CPU")
    except OSError:
        return "unknown CPU"


def hold_numerics(numerics: str, where: str, capability: Callable[[], str]) -> str:
    """Check that this process computes with ``numerics`` before it trains or judges; what it computes with, as a
    run's record says it (``"portable"``, or ``"native (AVX512)"``). ``capability()``: the vector kernels torch
    computes with in this process (torch's ``get_cpu_capability``, read once, when torch first computes).

    Raises:
        NumericsError: ``numerics`` is portable and the process's environment lacks :data:`PORTABLE` (a process not
            started by specguard's workers), or its torch already chose other kernels.
    """
    if numerics != "portable":
        return f"native ({capability()})"
    started = _STARTED if _STARTED is not None else os.environ
    missing = {k: v for k, v in PORTABLE.items() if not _holds(os.environ, k)}
    if LIBM not in started.get("GLIBC_TUNABLES", "").split(":"):
        missing["GLIBC_TUNABLES"] = LIBM
    if missing:
        said = ", ".join(f"{k}={(started if k == 'GLIBC_TUNABLES' else os.environ).get(k)!r}" for k in missing)
        raise NumericsError(
            f"{where}: portable numerics need {' '.join(f'{k}={v}' for k, v in missing.items())} in the environment "
            f"the process started with, and it has {said}"
        )
    chosen = capability()
    if chosen != "DEFAULT":
        raise NumericsError(
            f"{where}: portable numerics need torch's DEFAULT kernels, and this process's torch chose {chosen} before "
            "they were held"
        )
    return "portable"
