"""Checkpoint files: round trips of tensors, numpy arrays and plain values, the latest.json pointer
and its SHA-256, cleanup of older and stale files, the paths load_checkpoint accepts, damaged and
missing files, refusal of pickles that would run code (weights_only), and interrupted saves that
leave the previous checkpoint in place."""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
import torch

import evcd.utils.checkpoint as ckpt
from evcd.utils.checkpoint import (
    POINTER,
    CheckpointError,
    has_checkpoint,
    load_checkpoint,
    resolve,
    save_checkpoint,
    to_numpy,
    to_torch,
)


def _state(value: float = 1.0) -> dict:
    return {
        "weights": torch.full((3, 4), value),
        "nested": {"array": np.arange(6, dtype=np.int64).reshape(2, 3) * value, "list": [1, 2.5, "x"]},
        "value": value,
    }


def _pointer(directory: Path) -> dict:
    return json.loads((directory / POINTER).read_text())


def _pt_files(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.glob("*.pt"))


# -- round trips ----------------------------------------------------------------------------------------


def test_round_trip_of_nested_values(tmp_path):
    gen = np.random.default_rng(12345)
    gen.random(3)
    rng_state = gen.bit_generator.state  # PCG64: 128-bit Python ints
    assert rng_state["state"]["state"] > 2**64
    state = {
        "tensor": torch.arange(12, dtype=torch.float32).reshape(3, 4),
        "int_tensor": torch.tensor([1, -2, 3], dtype=torch.int64),
        "bool_tensor": torch.tensor([True, False]),
        "nested": {
            "array": np.linspace(0, 1, 7),
            "f32": np.ones((2, 2), dtype=np.float32),
            "bools": np.array([True, False, True]),
            "deeper": {"ints": np.array([3, 1, 4], dtype=np.int32), "scalar": np.float64(2.5)},
        },
        "rng": rng_state,
        "big": 2**100 + 7,
        "none": None,
        "nan": float("nan"),
        "inf": float("inf"),
        "tuple": (1, "two", 3.0, np.int64(4)),
        "list": [np.array([1.5]), None, {"k": "v"}],
        "text": "héllo",
        "flag": True,
    }
    save_checkpoint(tmp_path, state, "ckpt_1")
    loaded = load_checkpoint(tmp_path)

    assert torch.equal(loaded["tensor"], state["tensor"])
    assert torch.equal(loaded["int_tensor"], state["int_tensor"])
    assert torch.equal(loaded["bool_tensor"], state["bool_tensor"])
    # numpy arrays come back as tensors of the same dtype; to_numpy turns them back
    nested = loaded["nested"]
    assert isinstance(nested["array"], torch.Tensor)
    assert nested["array"].dtype == torch.float64
    arrays = to_numpy(nested)
    np.testing.assert_array_equal(arrays["array"], state["nested"]["array"])
    assert arrays["array"].dtype == np.float64
    np.testing.assert_array_equal(arrays["f32"], state["nested"]["f32"])
    assert arrays["f32"].dtype == np.float32
    np.testing.assert_array_equal(arrays["bools"], state["nested"]["bools"])
    assert arrays["bools"].dtype == np.bool_
    np.testing.assert_array_equal(arrays["deeper"]["ints"], [3, 1, 4])
    assert arrays["deeper"]["ints"].dtype == np.int32
    assert nested["deeper"]["scalar"] == 2.5
    assert type(nested["deeper"]["scalar"]) is float
    # the generator state restores the generator exactly
    assert loaded["rng"] == rng_state
    restored = np.random.default_rng(0)
    restored.bit_generator.state = loaded["rng"]
    np.testing.assert_array_equal(restored.random(5), gen.random(5))
    assert loaded["big"] == 2**100 + 7
    assert loaded["none"] is None
    assert math.isnan(loaded["nan"])
    assert loaded["inf"] == math.inf
    assert loaded["tuple"] == (1, "two", 3.0, 4)
    assert type(loaded["tuple"]) is tuple
    assert type(loaded["tuple"][3]) is int
    assert torch.equal(loaded["list"][0], torch.tensor([1.5], dtype=torch.float64))
    assert loaded["list"][1:] == [None, {"k": "v"}]
    assert loaded["text"] == "héllo"
    assert loaded["flag"] is True


def test_to_torch_and_to_numpy_are_inverse():
    value = {"a": np.arange(4.0), "b": [np.int8(3), (np.ones(2, np.float32), "s")], "c": None}
    as_torch = to_torch(value)
    assert isinstance(as_torch["a"], torch.Tensor)
    assert as_torch["b"][0] == 3
    assert type(as_torch["b"][0]) is int
    assert type(as_torch["b"][1]) is tuple
    assert isinstance(as_torch["b"][1][0], torch.Tensor)
    back = to_numpy(as_torch)
    np.testing.assert_array_equal(back["a"], value["a"])
    np.testing.assert_array_equal(back["b"][1][0], value["b"][1][0])
    assert back["b"][1][1] == "s"
    assert back["c"] is None
    # a non-contiguous array is stored contiguously
    strided = np.arange(12.0).reshape(3, 4)[:, ::2]
    np.testing.assert_array_equal(to_torch(strided).numpy(), strided)


def test_save_does_not_keep_aliases_of_the_state(tmp_path):
    state = {"w": torch.zeros(3)}
    save_checkpoint(tmp_path, state, "a")
    state["w"] += 1
    assert torch.equal(load_checkpoint(tmp_path)["w"], torch.zeros(3))


# -- files and pointer ----------------------------------------------------------------------------------


def test_only_the_newest_checkpoint_remains(tmp_path):
    names = ["ckpt_0000010", "ckpt_0000020", "ckpt_0000030", "final"]
    for i, name in enumerate(names):
        path = save_checkpoint(tmp_path, _state(float(i)), name)
        assert path == tmp_path / f"{name}.pt"
        assert _pt_files(tmp_path) == [f"{name}.pt"]
        pointer = _pointer(tmp_path)
        data = path.read_bytes()
        assert pointer["file"] == f"{name}.pt"
        assert pointer["sha256"] == hashlib.sha256(data).hexdigest()
        assert pointer["bytes"] == len(data)
        assert load_checkpoint(tmp_path)["value"] == float(i)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["final.pt", POINTER]


def test_older_checkpoints_named_in_keep_remain(tmp_path):
    for i, name in enumerate(["ckpt_0000010", "ckpt_0000020", "ckpt_0000030"]):
        save_checkpoint(tmp_path, _state(float(i)), name, keep=["ckpt_0000010"])
    assert _pt_files(tmp_path) == ["ckpt_0000010.pt", "ckpt_0000030.pt"]
    assert load_checkpoint(tmp_path)["value"] == 2.0  # the pointer names the newest
    assert load_checkpoint(tmp_path / "ckpt_0000010.pt")["value"] == 0.0


def test_saving_under_the_same_name_replaces_it(tmp_path):
    save_checkpoint(tmp_path, _state(1.0), "same")
    save_checkpoint(tmp_path, _state(2.0), "same")
    assert _pt_files(tmp_path) == ["same.pt"]
    assert load_checkpoint(tmp_path)["value"] == 2.0


def test_save_creates_the_folder_and_has_checkpoint(tmp_path):
    directory = tmp_path / "run" / "checkpoints"
    assert not has_checkpoint(directory)
    save_checkpoint(directory, _state(), "c")
    assert has_checkpoint(directory)
    assert not has_checkpoint(tmp_path / "run")


def test_stale_temporary_files_are_removed_on_save(tmp_path):
    save_checkpoint(tmp_path, _state(1.0), "one")
    stale = [tmp_path / ".two.pt.abc123.tmp", tmp_path / ".latest.json.x.tmp"]
    for path in stale:
        path.write_bytes(b"half a file")
    unrelated = tmp_path / "notes.txt"
    unrelated.write_text("keep me")
    save_checkpoint(tmp_path, _state(2.0), "two")
    assert not any(p.exists() for p in stale)
    assert unrelated.read_text() == "keep me"
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.parametrize("name", ["", "a/b", "../up", "with space", "dot.name", "tab\t", "x.pt/..", "é/"])
def test_bad_names_are_rejected(tmp_path, name):
    with pytest.raises(ValueError, match="name"):
        save_checkpoint(tmp_path / "c", _state(), name)
    assert not (tmp_path / "c" / POINTER).exists()
    assert not list(tmp_path.rglob("*.pt"))


def test_state_must_be_savable(tmp_path):
    save_checkpoint(tmp_path, {"a": 1}, "ok")
    with pytest.raises(TypeError):
        save_checkpoint(tmp_path, [1, 2], "bad")  # type: ignore[arg-type]
    assert load_checkpoint(tmp_path) == {"a": 1}


# -- what load_checkpoint accepts -----------------------------------------------------------------------


def test_resolve_and_load_accept_folder_pointer_run_dir_and_file(tmp_path):
    run_dir = tmp_path / "run"
    folder = run_dir / "checkpoints"
    path = save_checkpoint(folder, _state(3.0), "ckpt_3")
    sha = hashlib.sha256(path.read_bytes()).hexdigest()
    for where in (folder, folder / POINTER, run_dir, str(run_dir), str(folder)):
        assert resolve(where) == (path, sha)
        assert load_checkpoint(where)["value"] == 3.0
    assert resolve(path) == (path, None)  # a bare file: no checksum to check
    assert load_checkpoint(path)["value"] == 3.0
    # a bare .pt anywhere, e.g. copied out of its folder
    copy = tmp_path / "elsewhere.pt"
    copy.write_bytes(path.read_bytes())
    assert load_checkpoint(copy)["value"] == 3.0


def test_a_folder_with_its_own_pointer_wins_over_its_checkpoints_subfolder(tmp_path):
    save_checkpoint(tmp_path, _state(1.0), "outer")
    save_checkpoint(tmp_path / "checkpoints", _state(2.0), "inner")
    assert load_checkpoint(tmp_path)["value"] == 1.0


# -- damaged and missing files --------------------------------------------------------------------------


def test_flipped_byte_fails_the_checksum(tmp_path):
    path = save_checkpoint(tmp_path, _state(), "c")
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="corrupted or truncated") as info:
        load_checkpoint(tmp_path)
    assert str(path) in str(info.value)
    assert "SHA-256" in str(info.value)


def test_truncated_file_is_refused(tmp_path):
    path = save_checkpoint(tmp_path, _state(), "c")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="truncated") as info:
        load_checkpoint(tmp_path)
    assert str(path) in str(info.value)
    # without the pointer's checksum, torch.load itself fails and that is a CheckpointError too
    with pytest.raises(CheckpointError, match="corrupted, truncated") as info:
        load_checkpoint(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    "content", [b"", b"garbage, not a zip file at all", b"PK\x03\x04" + b"\x00" * 40, bytes(range(256)) * 8]
)
def test_bare_garbage_file_is_refused(tmp_path, content):
    path = tmp_path / "junk.pt"
    path.write_bytes(content)
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path)
    assert str(path) in str(info.value)


def test_bare_file_cut_at_every_tenth_is_refused(tmp_path):
    data = save_checkpoint(tmp_path / "src", _state(), "c").read_bytes()
    for k in range(1, 10):
        path = tmp_path / f"cut{k}.pt"
        path.write_bytes(data[: len(data) * k // 10])
        with pytest.raises(CheckpointError):
            load_checkpoint(path)


def test_a_non_dict_checkpoint_is_refused(tmp_path):
    path = tmp_path / "list.pt"
    torch.save([torch.ones(2)], path)
    with pytest.raises(CheckpointError, match="dict") as info:
        load_checkpoint(path)
    assert str(path) in str(info.value)


def test_pointer_naming_a_missing_file(tmp_path):
    path = save_checkpoint(tmp_path, _state(), "c")
    path.unlink()
    with pytest.raises(CheckpointError, match="missing") as info:
        load_checkpoint(tmp_path)
    assert str(tmp_path / POINTER) in str(info.value)
    assert "c.pt" in str(info.value)


@pytest.mark.parametrize(
    "text", ["", "{not json", "[]", '{"sha256": "00"}', '{"file": "c.pt"}', "null", '"c.pt"']
)
def test_malformed_pointer(tmp_path, text):
    save_checkpoint(tmp_path, _state(), "c")
    (tmp_path / POINTER).write_text(text)
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(tmp_path)
    assert str(tmp_path / POINTER) in str(info.value)


def test_pointer_with_a_wrong_checksum(tmp_path):
    save_checkpoint(tmp_path, _state(), "c")
    pointer = _pointer(tmp_path)
    pointer["sha256"] = "0" * 64
    (tmp_path / POINTER).write_text(json.dumps(pointer))
    with pytest.raises(CheckpointError, match="corrupted"):
        load_checkpoint(tmp_path)


@pytest.mark.parametrize("relative", ["nothing_here", "nothing_here/latest.json", "x.pt", "empty_dir"])
def test_missing_path(tmp_path, relative):
    (tmp_path / "empty_dir").mkdir()
    path = tmp_path / relative
    with pytest.raises(CheckpointError, match="no such file") as info:
        load_checkpoint(path)
    assert str(tmp_path / relative.split("/")[0]) in str(info.value)
    with pytest.raises(CheckpointError):
        resolve(path)


def test_checkpoint_error_is_a_value_error():
    assert issubclass(CheckpointError, ValueError)


@pytest.mark.parametrize("content", [b"not a checkpoint\n", b"PK\x03\x04 half a zip", b""])
def test_a_file_that_is_no_checkpoint_is_named_in_one_line_without_advice_to_unpickle(tmp_path, content):
    """What a user reads for a damaged file (tried: a text file given as agent.checkpoint): one line
    saying what is wrong and what to give instead, not torch's advice to load with weights_only=False."""
    path = tmp_path / "policy.pt"
    path.write_bytes(content)
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path)
    message = str(info.value)
    assert "\n" not in message and str(path) in message and "not an evcd checkpoint" in message
    assert "weights_only" not in message and "trusted source" not in message
    assert info.value.__cause__ is None and info.value.__suppress_context__


# -- weights_only ---------------------------------------------------------------------------------------

EXECUTED: list[str] = []


def _record(marker: str) -> None:
    EXECUTED.append(marker)


class Payload:
    """Unpickling this calls :func:`_record` (a code path that a loader must never run)."""

    def __init__(self, marker: str) -> None:
        self.marker = marker

    def __reduce__(self):
        return (_record, (self.marker,))


class ShellPayload:
    """Unpickling this runs a shell command through ``os.system``."""

    def __init__(self, target: Path) -> None:
        self.target = target

    def __reduce__(self):
        return (os.system, (f"touch {self.target}",))


class Plain:
    """A class instance: a full unpickler rebuilds it, weights_only refuses it."""

    def __init__(self) -> None:
        self.x = 1


@pytest.mark.parametrize("kind", ["reduce", "shell", "instance"])
def test_a_pickle_that_would_run_code_is_refused(tmp_path, kind):
    marker = tmp_path / "pwned"
    obj = {"reduce": Payload("ran"), "shell": ShellPayload(marker), "instance": Plain()}[kind]
    state = {"weights": torch.ones(2), "evil": obj}
    folder = tmp_path / "ckpt"
    save_checkpoint(folder, {"weights": torch.ones(2)}, "good")
    # a hostile file, saved with plain torch.save (full pickle) and a matching pointer
    path = folder / "evil.pt"
    torch.save(state, path)
    data = path.read_bytes()
    (folder / POINTER).write_text(json.dumps({"file": "evil.pt", "sha256": hashlib.sha256(data).hexdigest()}))
    EXECUTED.clear()
    for where in (folder, path):
        with pytest.raises(CheckpointError, match="corrupted, truncated or not an evcd checkpoint"):
            load_checkpoint(where)
    assert EXECUTED == []
    assert not marker.exists()
    if kind == "reduce":  # the file really is hostile: a full unpickler runs the payload
        torch.load(path, weights_only=False)
        assert EXECUTED == ["ran"]


# -- interrupted saves ----------------------------------------------------------------------------------


class SimulatedKillError(Exception):
    """Stands for the process dying mid-save."""


def _half_write_then_die(path, data):
    """What a process killed while writing leaves: half of a temporary file, nothing replaced."""
    path = Path(path)
    tmp = path.parent / f".{path.name}.k1ll3d.tmp"
    tmp.write_bytes(data[: len(data) // 2])
    raise SimulatedKillError(path)


def test_kill_while_writing_the_new_file_keeps_the_previous_one(tmp_path, monkeypatch):
    previous = save_checkpoint(tmp_path, _state(1.0), "ckpt_1")
    pointer = _pointer(tmp_path)
    monkeypatch.setattr(ckpt, "atomic_write_bytes", _half_write_then_die)
    with pytest.raises(SimulatedKillError):
        save_checkpoint(tmp_path, _state(2.0), "ckpt_2")
    assert list(tmp_path.glob(".*.tmp"))  # the half-written file is there
    assert not (tmp_path / "ckpt_2.pt").exists()
    assert _pointer(tmp_path) == pointer
    assert load_checkpoint(tmp_path)["value"] == 1.0
    assert resolve(tmp_path)[0] == previous
    # the next complete save goes through and cleans up
    monkeypatch.undo()
    save_checkpoint(tmp_path, _state(3.0), "ckpt_3")
    assert load_checkpoint(tmp_path)["value"] == 3.0
    assert not list(tmp_path.glob(".*.tmp"))
    assert _pt_files(tmp_path) == ["ckpt_3.pt"]


def test_kill_between_the_file_and_the_pointer_keeps_the_previous_one(tmp_path, monkeypatch):
    save_checkpoint(tmp_path, _state(1.0), "ckpt_1")
    pointer = _pointer(tmp_path)
    real = ckpt.atomic_write_text

    def die_on_pointer(path, text):
        if Path(path).name == POINTER:
            _half_write_then_die(path, text.encode())
        return real(path, text)

    monkeypatch.setattr(ckpt, "atomic_write_text", die_on_pointer)
    with pytest.raises(SimulatedKillError):
        save_checkpoint(tmp_path, _state(2.0), "ckpt_2")
    # the new file is complete, but the pointer still names the previous one, which is still there
    assert (tmp_path / "ckpt_2.pt").exists()
    assert _pointer(tmp_path) == pointer
    assert pointer["file"] == "ckpt_1.pt"
    assert load_checkpoint(tmp_path)["value"] == 1.0
    assert load_checkpoint(tmp_path / "ckpt_2.pt")["value"] == 2.0


def test_a_real_failed_write_leaves_no_temporary_file(tmp_path, monkeypatch):
    """The real atomic writer: an error while writing the temporary file removes it and leaves the
    previous checkpoint in place."""
    save_checkpoint(tmp_path, _state(1.0), "ckpt_1")
    pointer = _pointer(tmp_path)

    def failing_fsync(fd):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(OSError, match="disk full"):
        save_checkpoint(tmp_path, _state(2.0), "ckpt_2")
    assert not list(tmp_path.glob(".*.tmp"))
    assert not (tmp_path / "ckpt_2.pt").exists()
    assert _pointer(tmp_path) == pointer
    assert load_checkpoint(tmp_path)["value"] == 1.0
