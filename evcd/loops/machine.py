"""What a run's numbers were computed on, for its ``results.json``: the CPU, the instruction set torch's
kernels use on it, torch's threads, and the versions of the packages that shape the numbers.

A run is a function of its settings and its seed on one machine (docs/guide/getting-started.md, "Same
seed, same result"), but a learner's numbers also depend on how its floating-point kernels round, and
torch picks its kernels by the CPU's instruction set: the same seed and code gave another policy on an
AVX-512 CPU than on the machines before it (whose CPUs and package versions were not recorded), and on
that CPU ``ATEN_CPU_CAPABILITY=avx2`` alone gave another again, while the rules' episodes were
identical.
Recording the machine with the numbers lets a reader tell a difference of machine from one of code.
"""

from __future__ import annotations

import importlib.metadata
import os
import platform
from pathlib import Path
from typing import Any

#: The packages whose versions shape a run's numbers.
PACKAGES = ("torch", "numpy", "eclipse-sumo", "libsumo", "sumolib", "gymnasium", "hydra-core")
#: Environment variables that change which kernels torch and its BLAS use.
KERNEL_VARIABLES = ("ATEN_CPU_CAPABILITY", "MKL_CBWR", "ONEDNN_MAX_CPU_ISA", "OMP_NUM_THREADS")


def cpu_model(cpuinfo: Path = Path("/proc/cpuinfo")) -> str:
    """The CPU's model name (Linux's ``/proc/cpuinfo``), else what :func:`platform.processor` says."""
    try:
        for line in cpuinfo.read_text(errors="replace").splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def package_versions(names: tuple[str, ...] = PACKAGES) -> dict[str, str | None]:
    """Each package's installed version (``None``: not installed)."""
    versions: dict[str, str | None] = {}
    for name in names:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def machine_record() -> dict[str, Any]:
    """The machine a run's numbers come from: ``cpu`` (model name), ``cpu_capability`` (the instruction
    set torch's CPU kernels use, e.g. ``AVX512``), ``torch_threads``, ``platform``, ``python``,
    ``packages`` (:data:`PACKAGES`' versions) and the :data:`KERNEL_VARIABLES` that are set."""
    import torch  # here: reading results (evcd.report) must not pay for torch (tests/test_layering.py)

    return {
        "cpu": cpu_model(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "torch_threads": torch.get_num_threads(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "packages": package_versions(),
        "kernel_variables": {k: os.environ[k] for k in KERNEL_VARIABLES if k in os.environ},
    }
