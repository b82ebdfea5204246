"""End-to-end CLI runs: train writes a complete run folder, eval and act read it, bad input exits 2 cleanly."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import pytest


def mope_cli(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "mope.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=600)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "dst-mope"
    res = mope_cli("train", "--env", "deep-sea-treasure-v0", "--algo", "mope", "--steps", "300", "--seed", "0",
                   "--eval-every", "150", "--eval-prefs", "200", "--n-omega", "8", "--hidden", "32,32",
                   "--set", "learning_starts=50", "--set", "checkpoint_every=150", "--out", str(out), "--no-progress")
    assert res.returncode == 0, res.stderr
    assert "CR" in res.stdout and str(out) in res.stdout
    return out


def test_train_writes_a_complete_run_folder(run_dir):
    config = json.loads((run_dir / "config.json").read_text())
    assert config["algo"] == "mope" and config["total_steps"] == 300 and config["n_omega"] == 8
    assert config["hidden_sizes"] == [32, 32] and config["learning_starts"] == 50
    assert config["sigma_omega"] == 0.04  # defaults are resolved into the file too
    with open(run_dir / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(float(r["step"])) for r in rows] == [150, 300]
    for key in ("cr", "hv", "eum", "wall_s", "optimal_share", "eum_gap", "timeout_share"):
        assert key in rows[0]
    assert 0.0 <= float(rows[-1]["cr"]) <= 1.0
    assert (run_dir / "checkpoints" / "final.pt").is_file()
    assert (run_dir / "checkpoints" / "step_150.pt").is_file()
    assert list((run_dir / "tb").glob("events.out.tfevents.*"))
    with open(run_dir / "solutions.csv") as f:
        assert len(list(csv.DictReader(f))) == 200
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["algo"] == "mope" and summary["s_per_1k_steps"] > 0
    assert config["buffer_size"] is None and summary["resolved"] == {"epsilon_decay_steps": 10_000,
                                                                      "buffer_size": 20_000}


def test_eval_prints_metrics_and_writes_solutions(run_dir, tmp_path):
    out = tmp_path / "sols.csv"
    res = mope_cli("eval", str(run_dir), "--prefs", "100", "--out", str(out))
    assert res.returncode == 0, res.stderr
    for key in ("cr:", "hv:", "eum:", "optimal_share:"):
        assert key in res.stdout
    with open(out) as f:
        assert len(list(csv.DictReader(f))) == 100


def test_act_plays_one_episode(run_dir):
    res = mope_cli("act", str(run_dir / "checkpoints" / "final.pt"), "--pref", "0.3,0.7")
    assert res.returncode == 0, res.stderr
    assert "return: [" in res.stdout and "length:" in res.stdout


def test_train_refuses_to_overwrite_a_finished_run(run_dir):
    res = mope_cli("train", "--steps", "10", "--out", str(run_dir), "--no-progress")
    assert res.returncode == 2
    assert "already holds a run" in res.stderr
    assert (run_dir / "checkpoints" / "final.pt").is_file()  # the finished result is untouched


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["train", "--env", "deep-sea-treasur-v0", "--steps", "10"], "did you mean 'deep-sea-treasure-v0'"),
        (["train", "--algo", "mopee", "--steps", "10"], "unknown algorithm 'mopee'"),
        (["train", "--steps", "0"], "total_steps=0"),
        (["train", "--sigma-omega", "-1", "--steps", "10"], "sigma_omega=-1.0"),
        (["train", "--n-omega", "0", "--steps", "10"], "n_omega=0"),
        (["train", "--set", "gamma=1.5", "--steps", "10"], "gamma=1.5"),
        (["train", "--set", "batch_sze=3"], "did you mean 'batch_size'"),
        (["train", "--set", "batch_size=64", "--set", "buffer_size=10"], "buffer_size=10"),
        (["train", "--env", "mo-mountaincarcontinuous-v0", "--steps", "10"], "continuous action space"),
        (["eval", "does/not/exist.pt"], "neither a checkpoint file nor a run folder"),
    ],
)
def test_bad_input_exits_2_with_one_clear_line(args, message, tmp_path):
    res = mope_cli(*args, "--out", str(tmp_path / "x")) if args[0] == "train" else mope_cli(*args)
    assert res.returncode == 2, (res.stdout, res.stderr)
    assert message in res.stderr
    assert "Traceback" not in res.stderr
    assert res.stderr.strip().count("\n") == 0  # one line


@pytest.mark.parametrize(
    ("pref", "message"),
    [("0.3,0.3,0.4", "length 3"), ("-0.5,1.5", "negative"), ("nan,1", "NaN"), ("0.5,0.6", "sums to"),
     ("abc", "not a list of numbers")],
)
def test_act_rejects_bad_preferences(run_dir, pref, message):
    res = mope_cli("act", str(run_dir), "--pref", pref)
    assert res.returncode == 2
    assert message in res.stderr and "Traceback" not in res.stderr


def test_broken_checkpoint_is_named(tmp_path):
    bad = tmp_path / "broken.pt"
    bad.write_bytes(b"\x00garbage")
    res = mope_cli("eval", str(bad))
    assert res.returncode == 2
    assert "broken.pt" in res.stderr and "Traceback" not in res.stderr


def test_envs_lists_discrete_action_environments_only():
    res = mope_cli("envs")
    assert res.returncode == 0, res.stderr
    listed = res.stdout.split()
    assert "deep-sea-treasure-v0" in listed and "four-room-v0" in listed
    assert "mo-mountaincarcontinuous-v0" not in listed


def test_sweep_and_report_commands_fail_cleanly_on_bad_input(tmp_path):
    spec = tmp_path / "bad.yaml"
    spec.write_text("grid:\n  algo: [eql, mopee]\n")
    res = mope_cli("sweep", str(spec), "--out", str(tmp_path / "s"))
    assert res.returncode == 2 and "mopee" in res.stderr and "Traceback" not in res.stderr
    res = mope_cli("report", str(tmp_path / "empty"))
    assert res.returncode == 2 and "Traceback" not in res.stderr


def test_usage_errors_are_one_line():
    res = mope_cli("train", "--steps", "abc")
    assert res.returncode == 2
    assert res.stderr.strip().startswith("error:") and len(res.stderr.strip().splitlines()) == 1


def test_act_records_a_gif_and_refuses_other_formats(run_dir, tmp_path):
    gif = tmp_path / "episode.gif"
    res = mope_cli("act", str(run_dir), "--pref", "0.9,0.1", "--video", str(gif))
    assert res.returncode == 0, res.stderr
    assert gif.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    assert "frames" in res.stdout and "return:" in res.stdout
    res = mope_cli("act", str(run_dir), "--pref", "0.9,0.1", "--video", str(tmp_path / "episode.mp4"))
    assert res.returncode == 2 and "episode.mp4" in res.stderr and "Traceback" not in res.stderr


def test_reproduce_confrontation_rejects_a_bad_budget_mode(tmp_path):
    res = mope_cli("reproduce", "confrontation", "--ppo-budget", "half", "--out", str(tmp_path / "r"))
    assert res.returncode == 2 and "half" in res.stderr and "Traceback" not in res.stderr
