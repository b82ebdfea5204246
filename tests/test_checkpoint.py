"""Tests of mope.agent.checkpoint: round trips, atomic writes and refusing unsafe or broken files."""

from __future__ import annotations

import builtins
import io
import os
from pathlib import Path

import numpy as np
import pytest
import torch

import mope.agent.checkpoint as checkpoint
from mope.agent.checkpoint import FORMAT_VERSION, load_checkpoint, mope_version, save_checkpoint
from mope.config import Config
from mope.errors import CheckpointError, MopeError


def payload() -> dict:
    torch.manual_seed(0)
    return {
        "config": Config(seed=3).to_dict(),
        "weights": {"w": torch.arange(6, dtype=torch.float32).reshape(2, 3), "b": torch.tensor([0.5, -0.5])},
        "global_step": 1234,
        "name": "run",
        "counts": [1, 2, 3],
        "nested": {"x": [1.5, {"y": None}], "flag": True},
    }


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


class Evil:
    """Unpickling this creates a file: the kind of payload a checkpoint loader must refuse."""

    def __init__(self, target: Path) -> None:
        self.target = str(target)

    def __reduce__(self):  # noqa: ANN204
        return (builtins.open, (self.target, "w"))


# ------------------------------------------------------------------------------------------- round trip
def test_round_trip(tmp_path: Path) -> None:
    path = tmp_path / "ckpt.pt"
    out = save_checkpoint(path, payload())
    assert out == path and path.is_file()
    data = load_checkpoint(path)
    assert data["format_version"] == FORMAT_VERSION == 1
    assert data["mope_version"] == mope_version()
    assert data["config"] == Config(seed=3).to_dict()
    assert Config.from_dict(data["config"]) == Config(seed=3)
    torch.testing.assert_close(data["weights"]["w"], torch.arange(6, dtype=torch.float32).reshape(2, 3))
    torch.testing.assert_close(data["weights"]["b"], torch.tensor([0.5, -0.5]))
    assert data["global_step"] == 1234 and data["name"] == "run" and data["counts"] == [1, 2, 3]
    assert data["nested"] == {"x": [1.5, {"y": None}], "flag": True}
    assert leftovers(tmp_path) == []


def test_round_trip_of_a_module_state_dict_and_numpy_as_tensor(tmp_path: Path) -> None:
    net = torch.nn.Linear(3, 2)
    arr = np.arange(5, dtype=np.float32)
    save_checkpoint(tmp_path / "n.pt", {"config": {}, "net": net.state_dict(), "arr": torch.as_tensor(arr)})
    data = load_checkpoint(tmp_path / "n.pt")
    other = torch.nn.Linear(3, 2)
    other.load_state_dict(data["net"])
    x = torch.randn(4, 3)
    torch.testing.assert_close(other(x), net(x))
    np.testing.assert_array_equal(data["arr"].numpy(), arr)


def test_save_creates_parent_folders_and_overwrites(tmp_path: Path) -> None:
    path = tmp_path / "a" / "b" / "ckpt.pt"
    save_checkpoint(path, {"config": {}, "step": 1})
    save_checkpoint(path, {"config": {}, "step": 2})
    assert load_checkpoint(path)["step"] == 2
    assert leftovers(path.parent) == []


def test_payload_cannot_override_format_version(tmp_path: Path) -> None:
    # the payload is spread after the header, so a payload key wins; a stale version is then refused on load
    save_checkpoint(tmp_path / "c.pt", {"config": {}, "format_version": 99})
    with pytest.raises(CheckpointError, match="format version 99"):
        load_checkpoint(tmp_path / "c.pt")


# ------------------------------------------------------------------------------------------- atomic write
def test_crash_during_write_keeps_previous_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, payload())
    before = path.read_bytes()

    def broken_save(obj: object, f: io.BufferedWriter, *args: object, **kwargs: object) -> None:
        f.write(b"PK\x03\x04 partial checkpoint bytes")
        f.flush()
        raise OSError("disk full")

    monkeypatch.setattr(checkpoint.torch, "save", broken_save)
    with pytest.raises(CheckpointError, match="cannot write checkpoint .*ckpt.pt.*disk full"):
        save_checkpoint(path, {"config": {}, "step": 999})
    monkeypatch.undo()

    assert path.read_bytes() == before
    assert load_checkpoint(path)["global_step"] == 1234
    assert leftovers(tmp_path) == []
    assert sorted(os.listdir(tmp_path)) == ["ckpt.pt"]


def test_crash_on_first_write_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken_save(obj: object, f: io.BufferedWriter, *args: object, **kwargs: object) -> None:
        f.write(b"partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(checkpoint.torch, "save", broken_save)
    with pytest.raises(KeyboardInterrupt):
        save_checkpoint(tmp_path / "new.pt", {"config": {}})
    assert os.listdir(tmp_path) == []


# ------------------------------------------------------------------------------------------- broken files
def test_truncated_file(tmp_path: Path) -> None:
    path = tmp_path / "ckpt.pt"
    save_checkpoint(path, payload())
    raw = path.read_bytes()
    for keep in (len(raw) // 2, len(raw) - 10, 100, 10):
        path.write_bytes(raw[:keep])
        with pytest.raises(CheckpointError, match="ckpt.pt"):
            load_checkpoint(path)


def test_random_bytes(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    for i in range(5):
        path = tmp_path / f"junk{i}.pt"
        path.write_bytes(rng.integers(0, 256, size=2048, dtype=np.uint8).tobytes())
        with pytest.raises(CheckpointError, match=f"junk{i}.pt"):
            load_checkpoint(path)


def test_empty_file_and_text_file(tmp_path: Path) -> None:
    (tmp_path / "empty.pt").write_bytes(b"")
    with pytest.raises(CheckpointError):
        load_checkpoint(tmp_path / "empty.pt")
    (tmp_path / "text.pt").write_text('{"config": {}, "format_version": 1}')
    with pytest.raises(CheckpointError):
        load_checkpoint(tmp_path / "text.pt")


def test_missing_file_and_folder(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "nope.pt")
    with pytest.raises(CheckpointError, match="is a folder"):
        load_checkpoint(tmp_path)


def test_checkpoint_error_is_a_mope_error(tmp_path: Path) -> None:
    with pytest.raises(MopeError):
        load_checkpoint(tmp_path / "nope.pt")


# ------------------------------------------------------------------------------------------- unsafe files
def test_malicious_checkpoint_is_refused_without_running(tmp_path: Path) -> None:
    target = tmp_path / "pwned.txt"
    path = tmp_path / "evil.pt"
    torch.save({"format_version": FORMAT_VERSION, "config": {}, "x": Evil(target)}, path)
    assert not target.exists()
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(path)
    msg = str(info.value)
    assert "refused" in msg
    assert "evil.pt" in msg
    assert not target.exists()


def test_the_malicious_payload_is_real(tmp_path: Path) -> None:
    # control: an unsafe load of the same kind of file does run the payload (in tmp_path, harmlessly)
    target = tmp_path / "created.txt"
    path = tmp_path / "evil.pt"
    torch.save({"x": Evil(target)}, path)
    torch.load(path, weights_only=False)
    assert target.exists()


def test_arbitrary_class_instance_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "obj.pt"
    torch.save({"format_version": FORMAT_VERSION, "config": {}, "cfg": Config()}, path)
    with pytest.raises(CheckpointError, match="refused"):
        load_checkpoint(path)


# ------------------------------------------------------------------------------------------- not mope files
def test_dict_without_format_version(tmp_path: Path) -> None:
    path = tmp_path / "plain.pt"
    torch.save({"config": {}, "weights": torch.zeros(2)}, path)
    with pytest.raises(CheckpointError, match="not a mope checkpoint"):
        load_checkpoint(path)


def test_dict_without_config(tmp_path: Path) -> None:
    path = tmp_path / "noconfig.pt"
    torch.save({"format_version": FORMAT_VERSION}, path)
    with pytest.raises(CheckpointError, match="not a mope checkpoint"):
        load_checkpoint(path)


def test_not_a_dict(tmp_path: Path) -> None:
    path = tmp_path / "tensor.pt"
    torch.save(torch.zeros(3), path)
    with pytest.raises(CheckpointError, match="not a mope checkpoint"):
        load_checkpoint(path)


@pytest.mark.parametrize("version", [0, 2, 99, "1"])
def test_wrong_format_version(tmp_path: Path, version: object) -> None:
    path = tmp_path / "old.pt"
    torch.save({"format_version": version, "config": {}}, path)
    with pytest.raises(CheckpointError, match=f"format version {version}"):
        load_checkpoint(path)
