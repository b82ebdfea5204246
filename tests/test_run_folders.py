"""Run folder guards: never clobber a finished run, clear errors for unusable output paths."""

from __future__ import annotations

import pytest

from mope.errors import CheckpointError
from mope.experiments.runs import RunFolderError, prepare_out_dir, resolve_checkpoint


def test_output_path_that_is_a_file_is_refused(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(RunFolderError, match="exists and is not a folder"):
        prepare_out_dir(f)


def test_output_folder_that_cannot_be_created_is_named(tmp_path):
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(RunFolderError, match="not writable"):
        prepare_out_dir(f / "run")


def test_finished_run_is_not_overwritten_unless_asked(tmp_path):
    out = prepare_out_dir(tmp_path / "run")
    (out / "metrics.csv").write_text("step\n1\n")
    with pytest.raises(RunFolderError, match="already holds a run"):
        prepare_out_dir(out)
    assert (out / "metrics.csv").read_text() == "step\n1\n"
    assert prepare_out_dir(out, overwrite=True) == out


def test_resolve_checkpoint_prefers_final_then_newest_step(tmp_path):
    ck = tmp_path / "run" / "checkpoints"
    ck.mkdir(parents=True)
    with pytest.raises(CheckpointError, match="no checkpoint"):
        resolve_checkpoint(tmp_path / "run")
    for n in (500, 1500, 1000):
        (ck / f"step_{n}.pt").write_bytes(b"")
    assert resolve_checkpoint(tmp_path / "run").name == "step_1500.pt"
    (ck / "final.pt").write_bytes(b"")
    assert resolve_checkpoint(tmp_path / "run").name == "final.pt"
