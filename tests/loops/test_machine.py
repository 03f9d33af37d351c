"""The machine a run's numbers come from (evcd.loops.machine), as results.json records it."""

from __future__ import annotations

from importlib.metadata import version

import torch

from evcd.loops.machine import KERNEL_VARIABLES, cpu_model, machine_record, package_versions


def test_the_cpu_model_is_read_from_cpuinfo_else_from_the_platform(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD EPYC 9B14\nflags\t: fpu\n")
    assert cpu_model(info) == "AMD EPYC 9B14"
    assert cpu_model(tmp_path / "absent")  # no /proc: the platform's name, never empty


def test_package_versions_name_a_missing_package_none():
    versions = package_versions(("numpy", "no-such-package-evcd"))
    assert versions == {"numpy": version("numpy"), "no-such-package-evcd": None}


def test_the_record_names_torchs_kernels_threads_and_the_variables_that_change_them(monkeypatch):
    for name in KERNEL_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "default")
    record = machine_record()
    assert record["cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    assert record["torch_threads"] == torch.get_num_threads()
    assert record["kernel_variables"] == {"ATEN_CPU_CAPABILITY": "default"}
    assert record["packages"]["torch"] == torch.__version__ and record["packages"]["libsumo"] == version(
        "libsumo"
    )
    assert record["python"].count(".") == 2 and record["cpu"]
