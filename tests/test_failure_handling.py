"""Failure handling: nothing lost on a typo, no input hangs the tool, every failure is one line.

Each test reproduces one failure case: a failed ``--overwrite`` leaves
the old run byte for byte, YAML alias bombs are refused at once, and every other failure is one ``error:`` line,
exit code 2, no traceback.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from mope.config import Config
from mope.errors import ConfigError, MopeError, one_line
from mope.experiments.runs import RunFolderError, train_run

TINY = {"env_id": "deep-sea-treasure-v0", "algo": "eql", "total_steps": 60, "eval_every": 30, "eval_prefs": 10,
        "checkpoint_every": 30, "hidden_sizes": [8], "buffer_size": 200, "batch_size": 8, "learning_starts": 10,
        "n_omega": 4}
BOMB = "\n".join(["hidden_sizes:", "  - &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
                 + [f"  - &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)])


def tiny(**changes: object) -> Config:
    return Config.from_dict({**TINY, **changes})


def cli(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, *args: str) -> tuple[int, str, str]:
    """Run ``mope ARGS`` in this process; (exit code, stdout, stderr)."""
    from mope.cli import main

    monkeypatch.setattr(sys, "argv", ["mope", *args])
    with pytest.raises(SystemExit) as exit_:
        main()
    out = capsys.readouterr()
    return int(exit_.value.code or 0), out.out, out.err


def mope_cli(*args: str, **kwargs: object) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mope.cli", *args], capture_output=True, text=True, timeout=300,
                          **kwargs)


def one_error_line(err: str, *needles: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err and len(lines[0]) < 400, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


def tree_hash(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (relative path -> sha256 of its bytes)."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("finished") / "run"
    train_run(tiny(), out, progress=False)
    return out


@pytest.fixture
def old_run(finished_run: Path, tmp_path: Path) -> Path:
    """A copy of a finished run, to be overwritten."""
    out = tmp_path / "old"
    shutil.copytree(finished_run, out)
    return out


# --------------------------------------------------------------------------------------------- --overwrite
OVERWRITE_FAILURES = {
    "unknown env": (["--env", "foo-v0"], "unknown environment"),
    "continuous actions": (["--env", "mo-mountaincarcontinuous-v0"], "continuous action space"),
    "seed beyond 64 bits": (["--seed", str(2**64 + 5)], "64 bits"),
    "huge buffer": (["--set", "buffer_size=100000000000"], "GiB"),
    "bad eval prefs": (["--eval-prefs", "100000000"], "eval_prefs"),
    "cuda missing": (["--device", "cuda"], "cuda"),
}


@pytest.mark.parametrize("case", list(OVERWRITE_FAILURES))
def test_failed_overwrite_leaves_the_old_run_byte_for_byte(case: str, old_run: Path, capsys, monkeypatch) -> None:
    if case == "cuda missing" and torch.cuda.is_available():
        pytest.skip("this machine has CUDA")
    before = tree_hash(old_run)
    flags, needle = OVERWRITE_FAILURES[case]
    code, _, err = cli(capsys, monkeypatch, "train", "--algo", "eql", "--steps", "50", "--out", str(old_run),
                       "--overwrite", "--no-progress", *flags)
    assert code == 2
    one_error_line(err, needle)
    assert tree_hash(old_run) == before
    assert sorted(p.name for p in old_run.iterdir()) == sorted(p.name for p in old_run.iterdir()
                                                                if not p.name.startswith("."))


def test_overwrite_failing_before_its_first_checkpoint_restores_the_old_run(old_run: Path, monkeypatch) -> None:
    import mope.experiments.runs as experiments

    before = tree_hash(old_run)

    def broken_train(agent: object, steps: int, callbacks: list) -> None:
        (old_run / "metrics.csv").write_text("step\n1\n")  # the new run has started writing
        raise MopeError("the new run failed at step 5")

    monkeypatch.setattr(experiments, "train", broken_train)
    with pytest.raises(MopeError, match="step 5"):
        train_run(tiny(seed=1), old_run, progress=False, overwrite=True)
    assert tree_hash(old_run) == before
    assert not (old_run / ".overwritten").exists()


def test_overwrite_deletes_the_old_run_once_the_new_one_has_a_checkpoint(old_run: Path) -> None:
    old_final = (old_run / "checkpoints" / "final.pt").read_bytes()
    (old_run / "checkpoints" / "step_9999.pt").write_bytes(b"old")  # a file the new run will not write
    res = train_run(tiny(seed=1), old_run, progress=False, overwrite=True)
    assert res.agent.config.seed == 1
    assert not (old_run / ".overwritten").exists()
    assert not (old_run / "checkpoints" / "step_9999.pt").exists()
    assert (old_run / "checkpoints" / "final.pt").read_bytes() != old_final
    assert json.loads((old_run / "config.json").read_text())["seed"] == 1


def test_a_killed_overwrite_is_undone_on_the_next_start(old_run: Path) -> None:
    from mope.experiments.runs import _Aside, recover_aside

    before = tree_hash(old_run)
    _Aside.set_aside(old_run)  # what a SIGKILL between setting aside and the first checkpoint leaves
    (old_run / "checkpoints").mkdir()
    (old_run / "config.json").write_text("{}")
    assert not (old_run / "metrics.csv").exists()
    recover_aside(old_run)
    assert tree_hash(old_run) == before


def test_resume_of_another_config_names_a_command_that_works(old_run: Path, capsys, monkeypatch) -> None:
    (old_run / "summary.json").unlink()
    Config.from_dict({**TINY, "algo": "mope"}).save(old_run / "config.json")  # resume.pt is EQL's
    code, _, err = cli(capsys, monkeypatch, "train", "--resume", str(old_run), "--no-progress")
    line = one_error_line(err, "--overwrite")
    assert code == 2 and f"mope train --resume {old_run} --overwrite" in line
    code, out, err = cli(capsys, monkeypatch, "train", "--resume", str(old_run), "--overwrite", "--no-progress")
    assert code == 0, err
    assert "mope on deep-sea-treasure-v0" in out
    assert json.loads((old_run / "summary.json").read_text())["algo"] == "mope"


# --------------------------------------------------------------------------------------------- hostile files
def test_yaml_alias_bomb_config_is_refused_at_once(tmp_path: Path, capsys, monkeypatch) -> None:
    path = tmp_path / "bomb.yaml"
    path.write_text(BOMB)
    assert path.stat().st_size < 1024
    t0 = time.perf_counter()
    code, _, err = cli(capsys, monkeypatch, "train", "--config", str(path), "--out", str(tmp_path / "r"))
    assert time.perf_counter() - t0 < 1.0
    assert code == 2
    line = one_error_line(err, "bomb.yaml", "values")
    assert len(line) < 300
    assert not (tmp_path / "r").exists()


def test_yaml_alias_bomb_sweep_spec_and_set_are_refused_at_once(tmp_path: Path) -> None:
    from mope.experiments.sweep import SweepError, load_spec, parse_set

    path = tmp_path / "bomb.yaml"
    path.write_text("grid:\n" + "\n".join("  " + line for line in BOMB.splitlines()))
    assert path.stat().st_size < 1024
    t0 = time.perf_counter()
    with pytest.raises(SweepError) as exc:
        load_spec(path)
    assert time.perf_counter() - t0 < 1.0
    assert len(f"error: {exc.value}") < 300 and "values" in str(exc.value)
    flow = "[" + ", ".join(["&a [1, 1, 1, 1, 1, 1, 1, 1, 1]"] + ["*a"] * 8) + "]"
    assert parse_set([f"hidden_sizes={flow}"])["hidden_sizes"][0] == [1] * 9  # a harmless alias is fine
    nested = "&b0 [1,1,1,1,1,1,1,1,1,1]"
    for i in range(1, 7):
        nested = f"&b{i} [" + ", ".join([nested] + [f"*b{i - 1}"] * 9) + "]"
    with pytest.raises(SweepError, match="values"):
        parse_set([f"hidden_sizes={nested}"])


def test_a_recursive_yaml_alias_is_refused(tmp_path: Path) -> None:
    from mope.config import read_config_file

    path = tmp_path / "loop.yaml"
    path.write_text("hidden_sizes: &a [1, *a]\n")
    with pytest.raises(ConfigError, match="recursive"):
        read_config_file(path)


def test_values_in_errors_are_cut_short_and_every_error_is_capped() -> None:
    nested: list = [1] * 9
    for _ in range(9):
        nested = [nested] * 9  # 9**10 numbers if formatted whole
    t0 = time.perf_counter()
    with pytest.raises(ConfigError) as exc:
        Config(hidden_sizes=nested)
    assert time.perf_counter() - t0 < 1.0 and len(str(exc.value)) < 200
    long = MopeError("start " + "x" * 100_000 + " the fix")
    assert len(str(long)) <= 390 and str(long).startswith("start") and str(long).endswith("the fix")
    assert one_line("a\n  b") == "a b"


# --------------------------------------------------------------------------------------------- train
def test_seed_beyond_64_bits_is_one_line_and_leaves_no_folder(tmp_path: Path, capsys, monkeypatch) -> None:
    out = tmp_path / "r"
    code, _, err = cli(capsys, monkeypatch, "train", "--seed", str(2**64), "--steps", "20", "--out", str(out))
    assert code == 2
    one_error_line(err, "seed", "64 bits")
    assert not out.exists()
    cfg = tiny(seed=2**63 - 1)  # the largest seed trains
    assert train_run(cfg, tmp_path / "big", progress=False).agent.global_step == 60


def test_huge_buffer_is_refused_with_its_memory_before_allocating(tmp_path: Path, monkeypatch) -> None:
    import numpy as np

    import mope.experiments.runs as experiments

    allocated: list[int] = []
    real_zeros = np.zeros
    monkeypatch.setattr(np, "zeros", lambda shape, *a, **k: allocated.append(shape) or real_zeros(shape, *a, **k))
    with pytest.raises(MopeError, match=r"buffer_size=100000000000 needs about [\d.]+ GiB .* available"):
        train_run(tiny(buffer_size=100_000_000_000), tmp_path / "r", progress=False)
    assert not any(isinstance(s, tuple) and s and s[0] == 100_000_000_000 for s in allocated)
    need, per = experiments.estimate_memory(tiny(buffer_size=1000), experiments.make_env("deep-sea-treasure-v0"))
    assert 1000 * per < need and per > 16


def test_a_path_longer_than_the_file_system_allows_is_one_line(tmp_path: Path, capsys, monkeypatch) -> None:
    for out in (tmp_path / ("a" * 300) / "run", tmp_path / "/".join(["b" * 200] * 25)):
        code, _, err = cli(capsys, monkeypatch, "train", "--steps", "20", "--out", str(out), "--no-progress")
        assert code == 2
        one_error_line(err, "too long")


def _fill_disk_after(monkeypatch: pytest.MonkeyPatch, saves: int) -> None:
    """From the ``saves``-th checkpoint write on, fail as torch does on a full disk: an ENOSPC, then the zip writer's
    RuntimeError on top of it."""
    import mope.agent.checkpoint as checkpoint

    real_save = torch.save
    count = [0]

    def save(obj: object, f: object, *args: object, **kwargs: object) -> None:
        count[0] += 1
        if count[0] < saves:
            return real_save(obj, f, *args, **kwargs)
        try:
            raise OSError(28, "No space left on device")
        finally:
            raise RuntimeError("[enforce fail at inline_container.cc:672] . unexpected pos 35904 vs 35792")

    monkeypatch.setattr(checkpoint.torch, "save", save)
    monkeypatch.setattr(checkpoint, "_nearly_full", lambda folder: True)


def test_a_full_disk_is_one_line_that_says_how_to_continue(tmp_path: Path, capsys, monkeypatch) -> None:
    out = tmp_path / "r"
    _fill_disk_after(monkeypatch, 3)  # resume.pt and step_30.pt, then the disk is full
    code, _, err = cli(capsys, monkeypatch, "train", "--algo", "eql", "--steps", "60", "--set", "eval_prefs=10",
                       "eval_every=30", "checkpoint_every=30", "buffer_size=200", "batch_size=8", "learning_starts=10",
                       "--hidden", "8", "--out", str(out), "--no-progress")
    assert code == 2
    one_error_line(err, "disk", "full", f"mope train --resume {out}")
    assert (out / "checkpoints" / "resume.pt").is_file() and not list(out.glob("checkpoints/.*.tmp"))
    monkeypatch.undo()
    code, out_text, err = cli(capsys, monkeypatch, "train", "--resume", str(out), "--no-progress")
    assert code == 0, err


@contextlib.contextmanager
def small_disk(folder: Path) -> Iterator[Path]:
    folder.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=600k", "tmpfs", str(folder)],
                      capture_output=True).returncode != 0:
        pytest.skip("mounting a small tmpfs needs root")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], capture_output=True)


def test_a_really_full_disk_during_training_and_resume(tmp_path: Path) -> None:
    with small_disk(tmp_path / "disk") as disk:
        args = ["--steps", "400", "--set", "eval_prefs=10", "eval_every=100", "checkpoint_every=100",
                "buffer_size=2000", "--hidden", "16", "--no-progress"]
        for res in (mope_cli("train", *args, "--out", str(disk / "r")),
                    mope_cli("train", "--resume", str(disk / "r"), "--no-progress")):
            assert res.returncode == 2
            one_error_line(res.stderr, "full", "--resume")


# --------------------------------------------------------------------------------------------- eval
def test_eval_checks_where_results_go_before_evaluating(finished_run: Path, tmp_path: Path, capsys,
                                                        monkeypatch) -> None:
    import mope.evaluation.evaluator as evaluation

    def no_evaluation(*args: object, **kwargs: object) -> None:
        raise AssertionError("the evaluation ran before the output was checked")

    blocker = tmp_path / "file"
    blocker.write_text("x")
    with monkeypatch.context() as m:
        m.setattr(evaluation.Evaluator, "evaluate", no_evaluation)
        for out, needle in ((tmp_path, "is a folder"), (blocker / "x.csv", "is a file")):
            code, _, err = cli(capsys, monkeypatch, "eval", str(finished_run), "--prefs", "10", "--out", str(out))
            assert code == 2
            one_error_line(err, needle)
    target = tmp_path / "new" / "deeper" / "sols.csv"  # a folder that does not exist yet is made
    code, out, err = cli(capsys, monkeypatch, "eval", str(finished_run), "--prefs", "10", "--out", str(target))
    assert code == 0, err
    assert len(target.read_text().splitlines()) == 11


def test_eval_preference_count_is_bounded(finished_run: Path, capsys, monkeypatch) -> None:
    import mope.evaluation.evaluator as evaluation
    from mope.experiments.runs import evaluate_checkpoint

    t0 = time.perf_counter()
    code, _, err = cli(capsys, monkeypatch, "eval", str(finished_run), "--prefs", "10000000")
    assert code == 2 and time.perf_counter() - t0 < 30
    one_error_line(err, "10000000", str(evaluation.MAX_EVAL_PREFS))
    whole, sols = evaluate_checkpoint(finished_run, 40, seed=3)
    monkeypatch.setattr(evaluation, "EVAL_CHUNK", 7)  # rolled out in chunks: the same result
    chunked, sols7 = evaluate_checkpoint(finished_run, 40, seed=3)
    assert json.dumps(chunked, sort_keys=True) == json.dumps(whole, sort_keys=True)
    assert (sols7.discounted == sols.discounted).all() and (sols7.prefs == sols.prefs).all()


@contextlib.contextmanager
def read_only(folder: Path) -> Iterator[None]:
    """``folder`` read-only: by its mode, or (root writes anyway) by a read-only bind mount."""
    if os.geteuid() != 0:
        modes = {p: p.stat().st_mode for p in [folder, *folder.rglob("*")] if p.is_dir()}
        for p in modes:
            p.chmod(0o555)
        try:
            yield
        finally:
            for p, mode in modes.items():
                p.chmod(mode)
        return
    if subprocess.run(["mount", "--bind", "-o", "ro", str(folder), str(folder)], capture_output=True).returncode:
        pytest.skip("a read-only bind mount needs privileges this machine does not give")
    subprocess.run(["mount", "-o", "remount,ro,bind", str(folder)], capture_output=True)
    try:
        yield
    finally:
        subprocess.run(["umount", str(folder)], capture_output=True)


def test_eval_and_report_of_a_read_only_run_folder(old_run: Path, capsys, monkeypatch) -> None:
    with read_only(old_run):
        with contextlib.suppress(OSError):
            (old_run / "probe").write_text("x")
            pytest.skip("the folder could not be made read-only")
        code, _, err = cli(capsys, monkeypatch, "eval", str(old_run), "--prefs", "10")
        assert code == 2
        one_error_line(err, "--out")
        code, _, err = cli(capsys, monkeypatch, "report", str(old_run))
        assert code == 2
        one_error_line(err, "--out")
    code, _, err = cli(capsys, monkeypatch, "report", str(old_run), "--out", str(old_run.parent / "elsewhere"))
    assert code == 0, err


# --------------------------------------------------------------------------------------------- report
def test_report_out_naming_a_file_and_a_cell_that_is_not_a_number(old_run: Path, capsys, monkeypatch) -> None:
    code, _, err = cli(capsys, monkeypatch, "report", str(old_run), "--out", str(old_run / "config.json"))
    assert code == 2
    one_error_line(err, "is a file")
    rows = (old_run / "metrics.csv").read_text().splitlines()
    header = rows[0].split(",")
    cells = rows[2].split(",")
    cells[header.index("cr")] = "abc"
    (old_run / "metrics.csv").write_text("\n".join([*rows[:2], ",".join(cells), *rows[3:]]) + "\n")
    code, _, err = cli(capsys, monkeypatch, "report", str(old_run))
    assert code == 2
    one_error_line(err, "metrics.csv", "line 3", "cr", "'abc' is not a number")
    (old_run / "summary.json").unlink()
    code, _, err = cli(capsys, monkeypatch, "train", "--resume", str(old_run), "--no-progress")
    assert code == 2
    one_error_line(err, "metrics.csv", "'abc' is not a number")


def test_the_wrong_kind_of_path_is_named(old_run: Path, capsys, monkeypatch) -> None:
    for args, needle in ((["train", "--config", str(old_run)], "is a folder"),
                         (["sweep", str(old_run)], "is a folder"),
                         (["report", str(old_run / "config.json")], "is a file"),
                         (["train", "--resume", str(old_run / "config.json")], "is a file")):
        code, _, err = cli(capsys, monkeypatch, *args)
        assert code == 2
        line = one_error_line(err, needle)
        assert "does not exist" not in line


# --------------------------------------------------------------------------------------------- checkpoints
def test_random_bytes_are_not_called_a_dangerous_pickle(tmp_path: Path, capsys, monkeypatch) -> None:
    import pickle

    rnd = tmp_path / "rnd.pt"
    rnd.write_bytes(bytes(range(256)) * 20)
    old = tmp_path / "old.pt"
    old.write_bytes(pickle.dumps({"format_version": 1}, protocol=0))
    for path in (rnd, old):
        code, _, err = cli(capsys, monkeypatch, "eval", str(path))
        assert code == 2
        line = one_error_line(err, path.name, "not a mope checkpoint")
        assert "could run code" not in line


def test_stale_checkpoint_temporaries_are_removed_and_stats_keep_their_types(tmp_path: Path, monkeypatch) -> None:
    import mope.experiments.runs as experiments
    from mope.agent.runner import Callback

    ref = tmp_path / "ref"
    train_run(tiny(total_steps=90, log_every=10), ref, progress=False)
    out = tmp_path / "run"
    original_train = experiments.train

    class StopAt45(Callback):
        def on_step(self, agent: object, stats: object) -> bool:
            if agent.global_step == 45:  # type: ignore[attr-defined]
                signal.raise_signal(signal.SIGINT)
            return True

    monkeypatch.setattr(experiments, "train",
                        lambda agent, steps, cbs: original_train(agent, steps, [StopAt45(), *cbs]))
    with pytest.raises(KeyboardInterrupt):
        train_run(tiny(total_steps=90, log_every=10), out, progress=False)
    monkeypatch.undo()
    stale = out / "checkpoints" / ".resume.pt.x1y2z3.tmp"  # a checkpoint write cut short by a SIGKILL
    stale.write_bytes(b"partial")
    train_run(tiny(total_steps=90, log_every=10), out, progress=False, resume=True)
    assert not stale.exists()
    # the rows kept across the resume are written back as they were (100 stays 100, not 100.0)
    def before_45(folder: Path) -> list[str]:
        lines = (folder / "train_stats.csv").read_text().splitlines()
        return [line for line in lines[1:] if int(line.split(",")[0]) < 45]

    assert len(before_45(out)) >= 3 and before_45(out) == before_45(ref)
    with open(out / "train_stats.csv") as f:
        rows = list(csv.DictReader(f))
    assert rows[-1]["step"] == "90" and all(r["step"].isdigit() and r["updates"].isdigit() for r in rows)
    # the interval cut by the signal is two rows (41-45 before it, 46-50 after the resume): no update is lost
    with open(ref / "train_stats.csv") as f:
        ref_rows = list(csv.DictReader(f))
    updates = {int(r["step"]): int(r["updates"]) for r in rows}
    assert updates[45] + updates[50] == {int(r["step"]): int(r["updates"]) for r in ref_rows}[50]
    assert sum(updates.values()) == sum(int(r["updates"]) for r in ref_rows)


# --------------------------------------------------------------------------------------------- warnings
def test_warnings_are_not_printed_before_an_error_line(tmp_path: Path, capsys, monkeypatch) -> None:
    import mope.experiments.runs as experiments

    def noisy(*args: object, **kwargs: object) -> None:
        warnings.warn("a deprecation notice of some environment", UserWarning, stacklevel=1)
        raise RunFolderError("the real problem")

    def to_stderr(message: object, category: type, filename: str, lineno: int, file: object = None,
                  line: object = None) -> None:  # as an interpreter outside pytest shows a warning
        sys.stderr.write(warnings.formatwarning(message, category, filename, lineno))  # type: ignore[arg-type]

    monkeypatch.setattr(experiments, "train_run", noisy)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.showwarning = to_stderr
        code, _, err = cli(capsys, monkeypatch, "train", "--steps", "10", "--out", str(tmp_path / "r"))
    assert code == 2
    one_error_line(err, "the real problem")


# --------------------------------------------------------------------------------------------- video
def test_act_video_is_quiet_and_a_failed_write_is_one_line(finished_run: Path, tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("SDL_AUDIODRIVER", "SDL_VIDEODRIVER", "AUDIODEV")}
    res = mope_cli("act", str(finished_run), "--pref", "0.5,0.5", "--video", str(tmp_path / "v.gif"), env=env)
    assert res.returncode == 0 and res.stderr == "", res.stderr
    assert (tmp_path / "v.gif").read_bytes()[:3] == b"GIF"
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = mope_cli("act", str(finished_run), "--pref", "0.5,0.5", "--video", str(blocker / "v.gif"), env=env)
    assert res.returncode == 2
    one_error_line(res.stderr, "v.gif")
    from mope.evaluation.video import quiet_media

    monkeypatch = pytest.MonkeyPatch()
    monkeypatch.delenv("SDL_AUDIODRIVER", raising=False)
    try:
        quiet_media()
        assert os.environ["SDL_AUDIODRIVER"] == "dummy"
    finally:
        monkeypatch.undo()


# --------------------------------------------------------------------------------------------- sweeps
SWEEP = {"name": "s", "base": {k: v for k, v in TINY.items() if k != "algo"}, "grid": {"algo": ["eql"]}}


def _process_group(pgid: int) -> list[int]:
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == pgid:
            continue
        with contextlib.suppress(OSError, IndexError, ValueError):
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            if int(fields[2]) == pgid and fields[0] != "Z":
                pids.append(int(d.name))
    return pids


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads processes from /proc")
def test_sigkilled_sweep_leaves_no_process_behind(tmp_path: Path) -> None:
    spec = tmp_path / "spec.yaml"
    base = {**SWEEP["base"], "total_steps": 20_000, "eval_every": 0, "checkpoint_every": 200}
    spec.write_text(json.dumps({**SWEEP, "base": base, "seeds": 3}))
    sweep = subprocess.Popen([sys.executable, "-m", "mope.cli", "sweep", str(spec), "--out", str(tmp_path / "out"),
                              "--workers", "1", "--no-progress"], start_new_session=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while not list((tmp_path / "out").glob("*/checkpoints/step_*.pt")) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert _process_group(sweep.pid), "the sweep started no worker"
        os.kill(sweep.pid, signal.SIGKILL)
        sweep.wait()
        deadline = time.monotonic() + 10
        while _process_group(sweep.pid) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert _process_group(sweep.pid) == []
    finally:
        for pid in [sweep.pid, *_process_group(sweep.pid)]:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    # the interrupted trial kept its resumable state; the trials still queued were never started
    folders = sorted(p.name for p in (tmp_path / "out").iterdir() if p.is_dir())
    assert folders == ["deep-sea-treasure-v0-eql-s0"]
    assert (tmp_path / "out" / folders[0] / "checkpoints" / "resume.pt").is_file()


def test_huge_sweeps_are_announced_or_refused_and_sweep_json_is_not_rewritten_per_trial(tmp_path: Path, capsys,
                                                                                         monkeypatch) -> None:
    import mope.experiments.sweep as sweep_mod
    from mope.experiments.sweep import SweepError, load_spec, run_sweep

    spec = tmp_path / "huge.yaml"
    grid = {"target_update_freq": list(range(1, 1001)), "epsilon_decay_steps": list(range(1, 1001))}
    spec.write_text(json.dumps({**SWEEP, "grid": grid}))
    t0 = time.perf_counter()
    with pytest.raises(SweepError, match="1000000 trials"):
        run_sweep(load_spec(spec), tmp_path / "out", progress=False)
    assert time.perf_counter() - t0 < 5
    writes = []
    real_write = sweep_mod._write_sweep_json
    monkeypatch.setattr(sweep_mod, "_write_sweep_json", lambda *a, **k: writes.append(1) or real_write(*a, **k))

    def fake_run_jobs(jobs: list, out: Path, *args: object, on_done: object = None, **kwargs: object) -> dict:
        for job in jobs:
            on_done({"name": job.name, "status": "finished", "action": "trained", "final": {}, "wall_s": 0.0,
                     "error": None})
        return {}

    monkeypatch.setattr(sweep_mod, "run_jobs", fake_run_jobs)
    big = load_spec(spec)
    big.grid = {"target_update_freq": list(range(1, 1201))}
    results = run_sweep(big, tmp_path / "out", progress=False)
    assert len(results) == 1200
    assert len(writes) <= 5
    assert "this sweep has 1200 trials" in capsys.readouterr().err
    doc = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert [t["status"] for t in doc["trials"]] == ["finished"] * 1200


def test_a_finished_trial_loses_a_stale_error_file(tmp_path: Path, finished_run: Path) -> None:
    from mope.experiments.jobs import Job, run_jobs

    out = tmp_path / "batch"
    shutil.copytree(finished_run, out / "trial")
    (out / "trial" / "error.txt").write_text("FolderLockedError: in use by an orphaned worker")
    records = run_jobs([Job("trial", "train", tiny().to_dict())], out, progress=False)
    assert records["trial"]["action"] == "skipped"
    assert not (out / "trial" / "error.txt").exists()


def test_diagnose_measures_a_resource_gathering_run_and_refuses_an_unknown_environment(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """`mope diagnose` on a (tiny) resource-gathering run: the exact metrics, each in its range; on four-room,
    whose dynamics mope does not know, one error line and exit code 2."""
    rg = tiny(env_id="resource-gathering-v0", checkpoint_every=60)
    path = tmp_path / "rg.yaml"
    path.write_text(json.dumps(rg.to_dict()))
    code, _, err = cli(capsys, monkeypatch, "train", "--config", str(path), "--out", str(tmp_path / "rg"),
                       "--no-progress")
    assert code == 0, err
    code, out, err = cli(capsys, monkeypatch, "diagnose", str(tmp_path / "rg"), "--json", "--prefs", "20")
    assert code == 0, err
    d = json.loads(out)
    assert 0 <= d["path_error"] <= 1 and 0 <= d["greedy_utility_share"] <= 1 + 1e-9, d
    assert d["greedy_regret_mean"] >= -1e-9 and d["n_prefs"] == 15, d  # 15: the Das-Dennis lattice under 20
    four = tiny(env_id="four-room-v0", checkpoint_every=60)
    path.write_text(json.dumps(four.to_dict()))
    code, _, err = cli(capsys, monkeypatch, "train", "--config", str(path), "--out", str(tmp_path / "four"),
                       "--no-progress")
    assert code == 0, err
    code, _, err = cli(capsys, monkeypatch, "diagnose", str(tmp_path / "four"))
    assert code == 2
    one_error_line(err, "no ground truth for environment 'four-room-v0'")
