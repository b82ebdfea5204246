"""The agent's seams and the run machinery: variants from one config, collect/update/callbacks,
interval statistics in the logs, folder locks, `--set` with several pairs, `--resume` before the first
checkpoint, checkpoints that rebuild a wrapped environment, and reproductions through the job runner."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import mo_gymnasium as mo_gym
import numpy as np
import pytest

import mope
from mope import EQL, CheckpointError, Config, ConfigError, MoPE
from mope.agent.runner import Callback, IntervalStats, train
from mope.cli import expand_set_args
from mope.experiments.locks import LOCK_NAME, FolderLock, FolderLockedError
from mope.experiments.runs import train_run

SMALL = {"hidden_sizes": (16, 16), "n_omega": 4, "batch_size": 8, "learning_starts": 20, "buffer_size": 500,
         "disc_hidden": (8,)}


def cli(*args: str, cwd: Path | None = None, timeout: int = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "COLUMNS": "300", "TERM": "dumb"}
    return subprocess.run([sys.executable, "-m", "mope.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=timeout, env=env)


# ------------------------------------------------------------------------------------------- variants
def test_eql_refuses_a_config_of_another_variant() -> None:
    with pytest.raises(ConfigError, match="EQL needs a config of algorithm 'eql', got 'mope'"):
        EQL("deep-sea-treasure-v0", Config())
    agent = EQL("deep-sea-treasure-v0", Config.for_algo("eql", **SMALL))
    assert agent.algo == "eql" and agent.discriminator is None and not agent.pref_sampler.exploration
    assert type(mope.make_agent("eql", "deep-sea-treasure-v0", **SMALL)) is EQL
    assert type(mope.make_agent("pe", "deep-sea-treasure-v0", **SMALL)) is MoPE


def test_load_returns_the_saved_variant_and_eql_load_refuses_others(tmp_path: Path) -> None:
    EQL("deep-sea-treasure-v0", **SMALL).save(tmp_path / "eql.pt")
    MoPE("deep-sea-treasure-v0", **SMALL).save(tmp_path / "mope.pt")
    assert type(MoPE.load(tmp_path / "eql.pt")) is EQL
    assert type(EQL.load(tmp_path / "eql.pt")) is EQL
    assert type(MoPE.load(tmp_path / "mope.pt")) is MoPE
    with pytest.raises(CheckpointError, match="holds a 'mope' agent, not 'eql'"):
        EQL.load(tmp_path / "mope.pt")


def test_run_settings_are_separate_from_hyperparameters() -> None:
    c = Config(eval_prefs=100, seed=3)
    assert c.run.eval_prefs == 100 and "eval_prefs" not in Config.hyperparameter_names()
    assert c.to_dict()["eval_prefs"] == 100 and Config.from_dict(c.to_dict()) == c
    assert Config.from_dict({**c.to_dict(), "extra": {}}) == c  # a stray "extra" (0.1's empty field) is dropped


# ------------------------------------------------------------------------------------------- seams
def test_collect_step_acts_through_act_and_update_returns_its_statistics(monkeypatch: pytest.MonkeyPatch) -> None:
    agent = MoPE("deep-sea-treasure-v0", **SMALL)
    calls = []
    original = MoPE.act

    def spy(self: MoPE, obs: object, pref: object, greedy: bool = True) -> object:
        calls.append(greedy)
        return original(self, obs, pref, greedy)

    monkeypatch.setattr(MoPE, "act", spy)
    for _ in range(30):
        agent.collect_step()
    assert calls == [False] * 30 and agent.global_step == 30 and len(agent.buffer) == 30
    stats = agent.update()
    assert stats is agent.last_losses
    assert {"loss", "loss_a", "loss_b", "td_abs", "q_mean", "q_max", "mi_bonus", "disc_loss"} <= set(stats)
    assert all(np.isfinite(v) for v in stats.values())


def test_target_tau_end_anneals_the_polyak_weight_on_the_cosine() -> None:
    import torch

    from mope.agent.agent import polyak_weight

    agent = MoPE("deep-sea-treasure-v0", Config.for_algo("mope", **SMALL, total_steps=100, target_tau=0.01,
                                                         target_tau_end=0.001, target_tau_anneal_from=0.0))
    taus = [polyak_weight(agent.config, step) for step in (0, 50, 100, 200)]
    assert taus == pytest.approx([0.01, 0.0055, 0.001, 0.001])
    with torch.no_grad():  # one Polyak step at step 50 moves the target 0.0055 of the way to the online weights
        for p in agent.target_net.parameters():
            p.zero_()
    agent.global_step = 50
    agent._polyak()
    online, target = next(agent.q_net.parameters()), next(agent.target_net.parameters())
    assert torch.allclose(target, 0.0055 * online)
    assert polyak_weight(Config.for_algo("mope", **SMALL, total_steps=100, target_tau_end=None), 100) == 0.005
    default = Config.for_algo("mope", **SMALL, total_steps=100)  # the default: constant to half the run, then 1e-4
    assert [polyak_weight(default, step) for step in (50, 100)] == pytest.approx([0.005, 1e-4])
    late = Config.for_algo("mope", **SMALL, total_steps=100, target_tau=0.01, target_tau_end=0.001,
                           target_tau_anneal_from=0.5)  # constant over the first half, the cosine over the second
    assert [polyak_weight(late, step) for step in (0, 50, 75, 100)] == pytest.approx([0.01, 0.01, 0.0055, 0.001])
    assert all(polyak_weight(late, step) == 0.01 for step in range(51))  # exactly: the constant weight's run


def test_one_callback_object_sees_every_step_and_can_stop() -> None:
    agent = EQL("deep-sea-treasure-v0", **SMALL)

    class Recorder(Callback):
        def __init__(self) -> None:
            self.steps: list[int] = []
            self.updates = 0
            self.ended: bool | None = None

        def on_step(self, agent: MoPE, stats: dict | None) -> bool:
            self.steps.append(agent.global_step)
            self.updates += stats is not None
            return agent.global_step < 50

        def on_training_end(self, agent: MoPE, stopped: bool) -> None:
            self.ended = stopped

    rec = Recorder()
    assert train(agent, 100, rec) is False
    assert rec.steps == list(range(1, 51)) and rec.ended is True
    assert rec.updates == 50 - SMALL["learning_starts"]


def test_interval_statistics_average_the_updates() -> None:
    agent = EQL("deep-sea-treasure-v0", **SMALL)
    rows: list[dict] = []
    train(agent, 60, IntervalStats(20, rows.append))
    assert [r["step"] for r in rows] == [40, 60]  # no update before step 21: nothing to log at step 20
    assert rows[0]["updates"] == 20 and {"loss_a", "loss_b", "td_abs", "q_mean", "q_max"} <= set(rows[0])

def test_interval_statistics_report_the_training_episodes_with_known_answers() -> None:
    """On Deep-Sea-Treasure every step costs exactly -1 on the time objective and an episode ends only at a treasure
    or the time limit: the logged return of the time objective is minus the logged length, and the counts add up."""
    agent = EQL("deep-sea-treasure-v0", **SMALL)
    rows: list[dict] = []
    train(agent, 300, IntervalStats(100, rows.append))
    assert [r["step"] for r in rows] == [100, 200, 300]
    assert sum(r["episodes"] for r in rows) == agent.episodes > 0
    for r in rows:
        assert r["ep_return_1"] == pytest.approx(-r["ep_len"], rel=1e-6)
        assert 0.0 <= r["ep_end_share"] <= 1.0 and 0.0 <= r["ep_return_0"] <= 23.7
    assert agent.pop_episode_stats() == {}  # drained by the last row
    limited = EQL("deep-sea-treasure-v0", **{**SMALL, "max_episode_steps": 1, "epsilon_start": 0.0,
                                             "epsilon_end": 0.0})
    train(limited, 100, IntervalStats(100, rows.append))
    # the first step can reach the 0.7 treasure, else the time limit cuts the episode: ended in a terminal state or not
    last = rows[-1]
    assert last["episodes"] == 100 and last["ep_len"] == 1.0
    assert last["ep_end_share"] == pytest.approx(last["ep_return_0"] / 0.7)


@pytest.mark.slow
def test_interval_statistics_reach_the_run_folder_logs(tmp_path: Path) -> None:
    cfg = Config.for_algo("mope", **SMALL, total_steps=300, eval_every=150, eval_prefs=20, log_every=50,
                          checkpoint_every=0)
    train_run(cfg, tmp_path / "run", progress=False)
    with open(tmp_path / "run" / "train_stats.csv") as f:
        rows = list(csv.DictReader(f))
    assert [int(r["step"]) for r in rows] == [50, 100, 150, 200, 250, 300]
    assert all(float(r["updates"]) > 0 for r in rows[1:]) and float(rows[-1]["mi_bonus"]) == float(
        rows[-1]["mi_bonus"])  # not NaN for MoPE
    assert {"episodes", "ep_len", "ep_end_share", "ep_return_0", "ep_return_1"} <= set(rows[0])
    ended = [r for r in rows if float(r["episodes"]) > 0]  # NaN (False here) where no episode ended
    assert ended and all(float(r["ep_return_1"]) == pytest.approx(-float(r["ep_len"]), rel=1e-6) for r in ended)
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(tmp_path / "run" / "tb"))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    assert {"train/loss_a", "train/td_abs", "train/q_max", "train/mi_bonus", "train/ep_len", "eval/cr"} <= tags


# ------------------------------------------------------------------------------------------- locks
def test_a_second_writer_is_refused_and_a_stale_lock_is_taken_over(tmp_path: Path) -> None:
    folder = tmp_path / "run"
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        folder.mkdir()
        (folder / LOCK_NAME).write_text(json.dumps({"pid": sleeper.pid, "host": os.uname().nodename}))
        with pytest.raises(FolderLockedError, match=f"in use by process {sleeper.pid}"):
            FolderLock(folder, "run folder").acquire()
        cfg = Config.for_algo("eql", **SMALL, total_steps=30, eval_every=0, eval_prefs=5, checkpoint_every=0)
        with pytest.raises(FolderLockedError):
            train_run(cfg, folder, progress=False, overwrite=True)
        res = cli("train", "--algo", "eql", "--steps", "30", "--out", str(folder), "--overwrite", "--no-progress")
        assert res.returncode == 2 and "is in use by process" in res.stderr and "Traceback" not in res.stderr
    finally:
        sleeper.kill()
        sleeper.wait()
    # the holder is gone: its lock is stale and the next writer takes it over
    with FolderLock(folder, "run folder"):
        assert json.loads((folder / LOCK_NAME).read_text())["pid"] == os.getpid()
    assert not (folder / LOCK_NAME).exists()


# ------------------------------------------------------------------------------------------- command line
def test_one_set_takes_several_pairs() -> None:
    assert expand_set_args(["train", "--set", "a=1", "b=2", "--steps", "5"]) == \
        ["train", "--set", "a=1", "--set", "b=2", "--steps", "5"]
    assert expand_set_args(["sweep", "spec.yaml", "--set=a=1", "b=[1, 2]"]) == \
        ["sweep", "spec.yaml", "--set=a=1", "--set", "b=[1, 2]"]
    res = cli("train", "--set", "batch_size=8", "n_omegaa=3", "--steps", "10")
    assert res.returncode == 2 and "unknown config key 'n_omegaa'" in res.stderr  # the second pair was read


def test_train_help_shows_every_default() -> None:
    res = cli("train", "--help")
    for text in ("default: deep-sea-treasure-v0", "default: 20000", "default: 0]", "default: 1000",
                 "default: 2000", "default: 0.04", "default: 0.1", "default: 10", "default: cpu"):
        assert text in " ".join(res.stdout.replace("│", " ").split()), text


@pytest.mark.slow
def test_resume_of_a_run_killed_before_its_first_checkpoint_starts_it_over(tmp_path: Path) -> None:
    out = tmp_path / "run"
    out.mkdir()
    cfg = Config.for_algo("eql", **SMALL, total_steps=60, eval_every=0, eval_prefs=10, checkpoint_every=1000)
    cfg.save(out / "config.json")
    res = cli("train", "--resume", str(out), "--no-progress")
    assert res.returncode == 0, res.stderr
    assert "no checkpoint yet" in res.stderr and "starting it over" in res.stderr
    assert (out / "summary.json").is_file()
    # the same from Python
    (out / "summary.json").unlink()
    for f in (out / "checkpoints").glob("*.pt"):
        f.unlink()
    assert train_run(cfg, out, progress=False, resume=True).agent.global_step == 60


# ------------------------------------------------------------------------------------------- checkpoints
def test_a_checkpoint_rebuilds_the_wrapped_environment_it_was_trained_on(tmp_path: Path) -> None:
    from mope.envs import DiscreteActions
    from mope.envs.confrontation import RobotConfrontationEnv

    env = DiscreteActions(mo_gym.make("mope/RobotConfrontation-v0"), bins=3)
    MoPE(env, **SMALL).save(tmp_path / "wrapped.pt")
    back = MoPE.load(tmp_path / "wrapped.pt")
    assert isinstance(back.env, DiscreteActions) and back.env.action_space.n == 9
    hand = MoPE(DiscreteActions(RobotConfrontationEnv(), bins=3), **SMALL)
    assert hand.config.env_id == "RobotConfrontationEnv"
    hand.save(tmp_path / "hand.pt")
    with pytest.raises(CheckpointError, match="cannot be rebuilt .* MoPE.load\\(path, env=your_env\\)"):
        MoPE.load(tmp_path / "hand.pt")
    assert MoPE.load(tmp_path / "hand.pt", env=DiscreteActions(RobotConfrontationEnv(), bins=3)).n_actions == 9


def test_a_checkpoint_of_the_mirrored_map_loads_without_env(tmp_path: Path) -> None:
    """MO-Gymnasium registers the mirrored map as a numpy array that JSON cannot hold: the checkpoint names the
    registration's argument and takes it from the registry on load (it used to refuse to load without env=)."""
    agent = MoPE("deep-sea-treasure-mirrored-v0", **SMALL)
    agent.save(tmp_path / "mirrored.pt")
    back = MoPE.load(tmp_path / "mirrored.pt")
    assert np.array_equal(back.env.unwrapped.sea_map, agent.env.unwrapped.sea_map)
    assert back.env.unwrapped.sea_map.shape == (11, 20)
    obs, w = np.array([[0, 10]]), np.array([[0.3, 0.7]])
    np.testing.assert_array_equal(back.q_values(obs, w), agent.q_values(obs, w))


# ------------------------------------------------------------------------------------------- job runner
@pytest.mark.slow
def test_an_interrupted_reproduction_resumes_through_the_job_runner(tmp_path: Path, monkeypatch) -> None:
    import signal

    import mope.experiments.runs as experiments
    from mope.paper.dst import dst_jobs, reproduce_dst, run_name

    tiny = {**SMALL, "eval_prefs": 50, "checkpoint_every": 100}
    out = tmp_path / "repro"
    job = dst_jobs(1, 300, 150, ("eql",), **tiny)[0]
    original = experiments.train

    class SigintAt200(Callback):
        def on_step(self, agent: MoPE, stats: object) -> bool:
            if agent.global_step == 200:
                signal.raise_signal(signal.SIGINT)
            return True

    monkeypatch.setattr(experiments, "train", lambda a, n, cbs: original(a, n, [SigintAt200(), *cbs]))
    with pytest.raises(KeyboardInterrupt):
        train_run(Config.from_dict(job.payload), out / run_name("eql", 0), progress=False)
    monkeypatch.setattr(experiments, "train", original)
    res = reproduce_dst(out, seeds=1, steps=300, eval_every=150, algos=("eql",), workers=1, progress=False, **tiny)
    assert res["records"]["eql-s0"]["action"] == "resumed"
    train_run(Config.from_dict(job.payload), tmp_path / "straight", progress=False)
    assert _rows(out / "eql-s0") == _rows(tmp_path / "straight")  # resumed = uninterrupted, row for row


def _rows(folder: Path) -> list[dict[str, str]]:
    with open(folder / "metrics.csv") as f:
        return [{k: v for k, v in r.items() if k not in ("wall_s", "train_s")} for r in csv.DictReader(f)]


# ------------------------------------------------------------------------------------------- benchmark
@pytest.mark.parametrize(("args", "needle"), [
    (["--envs", "deep-sea-treasur-v0"], "unknown environment 'deep-sea-treasur-v0'"),
    (["--methods", "mopee"], "unknown method 'mopee' (did you mean 'mope'?)"),
    (["--methods", "mope-late-bound"], "method 'mope-late-bound' was renamed 'mope-bound-eps10k'"),
    (["--methods", "mope-bound"], "method 'mope-bound' was renamed 'mope-eps-greedy' when the seen-return bound"),
    (["--methods", "eql-late"], "method 'eql-late' was renamed 'eql-eps10k' (the late target anneal"),
    (["--envs", "mope/RobotConfrontation-v0"], "continuous action space"),
    (["--steps", "0"], "--steps 0 is out of range"),
    (["--seeds", "0"], "--seeds=0 is out of range"),
    (["--seeds", "5-"], "--seeds='5-' is not a count (5), a range (5-9) or a list of seeds (0,5,7)"),
    (["--seeds", "1,1"], "lists a seed twice"),
])
def test_benchmark_bad_input_is_one_line(tmp_path: Path, args: list[str], needle: str) -> None:
    res = cli("benchmark", "--out", str(tmp_path / "b"), "--methods", "mope", *args)
    assert res.returncode == 2 and needle in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr


@pytest.mark.slow
def test_benchmark_quick_runs_and_keeps_finished_runs(tmp_path: Path) -> None:
    out = tmp_path / "bench"
    # --steps 300: every environment and file of --quick, 100 updates after learning_starts, for the defaults. The
    # learning itself is tested elsewhere, the methods' configs by test_benchmark_older_methods_are_the_defaults_
    # they_ran_with. --quick's own budgets took 10 minutes of this suite; --steps 500 with a preset beside the
    # defaults took 145 s.
    quick = ("benchmark", "--quick", "--steps", "300", "--methods", "mope", "--out", str(out),
             "--no-progress")
    res = cli(*quick, timeout=1500)
    assert res.returncode == 0, res.stderr
    assert "benchmark: 4 runs into" in res.stderr and "mope; seed 0" in res.stderr  # the plan, before training
    text = (out / "benchmark.md").read_text()
    for env_id in ("deep-sea-treasure-v0", "resource-gathering-v0", "minecart-deterministic-v0", "four-room-v0"):
        assert f"## {env_id}" in text and (out / f"{env_id}.png").is_file()
    summary = json.loads((out / "benchmark.json").read_text())["summary"]
    assert summary["deep-sea-treasure-v0"]["_meta"]["known_front"] is True
    # four-room publishes no front; mope evaluates against the stored exact one (mope.evaluation.four_room)
    assert summary["four-room-v0"]["_meta"]["optimal_eum"] == pytest.approx(3.580, abs=1e-3)
    stamp = (out / "deep-sea-treasure-v0-mope-s0" / "summary.json").stat().st_mtime
    again = cli(*quick)  # a re-run keeps the finished runs
    assert again.returncode == 0 and (out / "deep-sea-treasure-v0-mope-s0" / "summary.json").stat().st_mtime == stamp


def test_the_benchmark_plan_names_the_seeds_it_trains() -> None:
    """``--seeds 4`` trains seeds 0-3 (a count), ``--seeds 4-4`` seed 4: the line printed before training says which."""
    from mope.experiments.sweep import seed_list
    from mope.paper.benchmark import plan_line

    assert plan_line(["four-room-v0"], ["eql"], seed_list("4"), Path("b")).endswith("eql; seeds 0-3")
    line = plan_line(["four-room-v0", "minecart-deterministic-v0"], ["eql", "mope"], seed_list("4-4"), Path("b"))
    assert line.startswith("benchmark: 4 runs into b") and line.endswith("eql, mope; seed 4")
    assert plan_line(["four-room-v0"], ["eql"], seed_list("0,5,7"), Path("b")).endswith("seeds 0, 5, 7")


def _fake_bench_run(out: Path, env_id: str, method: str, seed: int, steps: int, cr: float) -> None:
    """A finished benchmark run folder as ``mope benchmark`` leaves it (compact files only)."""
    from mope.experiments.runs import METRIC_COLUMNS

    folder = out / f"{env_id}-{method}-s{seed}"
    folder.mkdir(parents=True)
    meta = "peer.json" if method.startswith("envelope") else "config.json"
    (folder / meta).write_text(json.dumps({"env_id": env_id, "seed": seed, "total_steps": steps}))
    with open(folder / "metrics.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=METRIC_COLUMNS, restval="nan")
        w.writeheader()
        for step, c in ((steps // 2, cr / 2), (steps, cr)):
            w.writerow({"step": step, "wall_s": step / 100, "train_s": step / 100, "cr": c, "eum": 5.6 * c,
                        "hv": 300 * c})
    (folder / "summary.json").write_text(json.dumps({"final": {"cr": cr}, "train_s_per_1k_steps": 10.0,
                                                     "peak_rss_mb": 400.0}))


def test_benchmark_report_covers_every_committed_piece(tmp_path: Path) -> None:
    """Pieces run apart (other seeds, another method, another session) make one table; budgets must agree."""
    from mope.errors import MopeError
    from mope.paper.benchmark import GITIGNORE, run_benchmark

    out = tmp_path / "bench"
    _fake_bench_run(out, "deep-sea-treasure-v0", "mope", 0, 20_000, 1.0)
    _fake_bench_run(out, "deep-sea-treasure-v0", "mope", 1, 20_000, 0.8)
    _fake_bench_run(out, "deep-sea-treasure-v0", "envelope", 0, 20_000, 0.6)
    (out / "notes").mkdir()  # not a run: ignored
    res = run_benchmark(out, report_only=True, progress=False, command="mope benchmark --report-only")
    text = (out / "benchmark.md").read_text()
    dst = res["summary"]["deep-sea-treasure-v0"]
    assert dst["mope"]["seeds"] == 2 and dst["envelope"]["seeds"] == 1
    assert dst["mope"]["stats"]["cr"]["mean"] == pytest.approx(0.9)
    # EUM 5.6 x CR at both evaluations (CR / 2, CR): the last evaluations' mean is 4.2 x CR, over seeds 3.78
    assert dst["mope"]["stats"]["eum_last"]["mean"] == pytest.approx(3.78)
    # the target is 95 % of DST's optimal EUM (5.563, though the fake runs recorded none): seed 0 reached it at its
    # last evaluation (5.6), seed 1 never (4.48)
    assert dst["mope"]["reached"] == 1
    assert "## deep-sea-treasure-v0" in text and "Ratios to Envelope" in text
    assert (out / "deep-sea-treasure-v0.png").is_file()
    code = json.loads((out / "benchmark.json").read_text())["info"]["code"]  # which mope trained (commit if any)
    assert code.startswith("mope ") and f"; {code}: `mope benchmark --report-only`" in text

    _fake_bench_run(out, "resource-gathering-v0", "mope", 0, 50_000, 0.5)  # stochastic: no CR, HV or optimal share
    run_benchmark(out, report_only=True, progress=False)
    text = (out / "benchmark.md").read_text()
    rg = text[text.index("## resource-gathering-v0"):]
    assert "Stochastic dynamics" in rg and "| CR |" not in rg and "| HV |" not in rg and "| EUM |" in rg
    assert "| CR |" in text[:text.index("## resource-gathering-v0")]
    rows = (out / "readme_table.md").read_text().splitlines()
    assert next(r for r in rows if r.startswith("| resource-gathering-v0")).split("|")[5].strip() == "-"
    shutil.rmtree(out / "resource-gathering-v0-mope-s0")

    _fake_bench_run(out, "deep-sea-treasure-v0", "eql", 0, 10_000, 1.0)  # another budget: cannot share the table
    with pytest.raises(MopeError, match="different budgets"):
        run_benchmark(out, report_only=True, progress=False)
    shutil.rmtree(out / "deep-sea-treasure-v0-eql-s0")
    res = cli("benchmark", "--out", str(out), "--envs", "deep-sea-treasure-v0", "--methods", "eql", "--steps", "500")
    assert res.returncode == 2 and "holds deep-sea-treasure-v0 runs of 20,000 steps" in res.stderr, res.stderr
    assert not (out / "deep-sea-treasure-v0-eql-s0").exists()  # refused before training

    empty = tmp_path / "empty"
    empty.mkdir()
    res = cli("benchmark", "--report-only", "--out", str(empty))
    assert res.returncode == 2 and "holds no finished benchmark run" in res.stderr
    assert "*/*" in GITIGNORE and "!*/metrics.csv" in GITIGNORE


def test_readme_table_marks_a_cr_the_runs_did_not_record() -> None:
    """Runs that predate an environment's exact front have no CR: the cell says so with a footnote, not a bare n/a."""
    from mope.paper.benchmark import readme_table

    def stats(n: int, mean: float = 1.0) -> dict[str, float]:
        return {"n": n, "mean": mean, "ci_low": mean, "ci_high": mean}

    def method(cr_n: int) -> dict[str, object]:
        return {"seeds": 2, "reached": 0, "stats": {"cr": stats(cr_n, 0.0), "eum": stats(2), "eum_last": stats(2),
                                                       "eum_gap": stats(2), "hv": stats(2)}}

    meta = {"known_front": True, "optimal_eum": 3.0, "stochastic": False, "steps": 1000}
    table = readme_table({"four-room-v0": {"_meta": meta, "mope": method(0), "eql": method(2)}})
    rows = {r.split("|")[3].strip(): r.split("|")[5].strip() for r in table.splitlines()[2:] if r.startswith("|")}
    assert rows == {"mope": "n/a *", "eql": "0.000 [0.000, 0.000]"}
    assert "\\* These runs ran before mope knew" in table
    assert "These runs ran" not in readme_table({"four-room-v0": {"_meta": meta, "eql": method(2)}})


def test_readme_benchmark_table_is_the_committed_results() -> None:
    """The README's benchmark table is the one ``mope benchmark`` generates from docs/results/benchmark."""
    from mope.paper.benchmark import README_MARKERS, readme_table

    root = Path(__file__).resolve().parents[1]
    summary = json.loads((root / "docs/results/benchmark/benchmark.json").read_text())["summary"]
    readme = (root / "README.md").read_text()
    start, end = (readme.index(m) for m in README_MARKERS)
    block = readme[start + len(README_MARKERS[0]):end].strip("\n") + "\n"
    assert block == readme_table(summary)
    assert block == (root / "docs/results/benchmark/readme_table.md").read_text()
    rows = [row for row in block.splitlines()[2:] if row.startswith("|")]
    methods = {row.split("|")[3].strip() for row in rows}  # today's, the two before, the peer
    assert {"mope", "envelope"} <= methods <= {"mope", "eql", "mope-lb-w1", "mope-lb-abs", "eql-lb-abs", "envelope"}
    assert "| mope-const |" in (root / "docs/results/benchmark/benchmark.md").read_text()  # the others: there


def test_benchmark_mope_eps_greedy_is_the_defaults_with_one_step_exploration(tmp_path: Path) -> None:
    """The defaults bound the targets by the returns seen and explore with ez-greedy; ``mope-eps-greedy`` is them with
    one-step epsilon-greedy (the runs named ``mope-bound`` before 2026-12-07): its jobs' configs, and its committed
    runs found by name."""
    from mope.paper.benchmark import benchmark_jobs, finished_runs, summarise

    jobs = benchmark_jobs(["four-room-v0"], ["mope", "mope-eps-greedy"], [0], quick=False, steps=None)
    by_name = {j.name: j.payload for j in jobs}
    assert by_name["four-room-v0-mope-s0"]["seen_bound_margin"] == 0.1
    assert by_name["four-room-v0-mope-s0"]["epsilon_repeat_mu"] == 2.0
    assert by_name["four-room-v0-mope-eps-greedy-s0"]["seen_bound_margin"] == 0.1
    assert by_name["four-room-v0-mope-eps-greedy-s0"]["epsilon_repeat_mu"] is None
    out = tmp_path / "bench"
    _fake_bench_run(out, "four-room-v0", "mope-eps-greedy", 0, 50_000, 0.5)
    _fake_bench_run(out, "four-room-v0", "mope", 0, 50_000, 0.25)
    found = finished_runs(out)
    assert sorted(j.name for j in found) == ["four-room-v0-mope-eps-greedy-s0", "four-room-v0-mope-s0"]
    table = summarise(out, found)["four-room-v0"]
    assert table["mope-eps-greedy"]["stats"]["eum"]["mean"] == pytest.approx(2.8)
    assert table["mope"]["stats"]["eum"]["mean"] == pytest.approx(1.4)


def test_benchmark_older_methods_are_the_defaults_they_ran_with(tmp_path: Path) -> None:
    """Each older method differs from the next newer one by the fields of one switch, so the runs committed before
    each switch keep their config under their new names, found by name beside the defaults': ``mope-lb-w1`` from
    ``mope`` by the weight 1 of L^B (:data:`LB_W1`), ``*-lb-abs`` from ``mope-lb-w1`` and ``eql`` by the absolute
    L^B of weight 1, ``mope-eps-greedy`` from ``mope-lb-abs`` by one-step
    exploration (:data:`PLAIN_EPSILON`), ``*-eps-greedy-unbounded`` from those by the seen-return bound
    (:data:`UNBOUNDED`), ``*-eps10k`` from those by epsilon's decay and the buffer (:data:`SHORT_EXPLORATION`), and
    ``*-const`` from those by the late target anneal and ``reward_norm``."""
    from mope.config import CONSTANT_TARGET, PLAIN_EPSILON, SHORT_EXPLORATION, UNBOUNDED
    from mope.paper.benchmark import LB_ABS, LB_W1, METHODS, RENAMED_METHODS, benchmark_jobs, finished_runs

    assert all(new in METHODS for new, _ in RENAMED_METHODS.values())  # every old name points at a method
    c = Config()
    assert (c.target_tau_end, c.target_tau_anneal_from, c.epsilon_repeat_mu, c.seen_bound_margin, c.lb_loss,
            c.lb_weight) == (1e-4, 0.5, 2.0, 0.1, "squared", 4.0)
    methods = ["mope", "mope-lb-w1", "mope-lb-abs", "mope-eps-greedy", "mope-eps-greedy-unbounded", "mope-eps10k",
               "mope-const", "eql", "eql-lb-abs", "eql-eps-greedy-unbounded", "eql-eps10k", "eql-const",
               "mope-bound-eps10k", "mope-const-bound", "mope-paper"]
    jobs = benchmark_jobs(["resource-gathering-v0"], methods, [1], quick=False, steps=None)
    by_name = {j.name.removeprefix("resource-gathering-v0-").removesuffix("-s1"): j.payload for j in jobs}

    def changed(old: str, new: str) -> dict:
        return {k: by_name[old][k] for k in by_name[old] if by_name[old][k] != by_name[new][k]}

    assert changed("mope-lb-w1", "mope") == LB_W1
    assert changed("mope-lb-abs", "mope-lb-w1") == LB_ABS
    assert changed("eql-lb-abs", "eql") == {**LB_W1, **LB_ABS}
    assert (by_name["mope-paper"]["lb_loss"], by_name["mope-paper"]["lb_weight"]) == ("abs", 1.0)  # eq. 4 as written
    assert changed("mope-eps-greedy", "mope-lb-abs") == PLAIN_EPSILON
    assert changed("mope-eps-greedy-unbounded", "mope-eps-greedy") == UNBOUNDED
    assert changed("eql-eps-greedy-unbounded", "eql-lb-abs") == {**PLAIN_EPSILON, **UNBOUNDED}
    for now in ("mope-eps-greedy-unbounded", "eql-eps-greedy-unbounded"):
        assert changed(now.replace("eps-greedy-unbounded", "eps10k"), now) == SHORT_EXPLORATION
    assert changed("mope-bound-eps10k", "mope-eps-greedy") == SHORT_EXPLORATION
    for short, const in (("mope-eps10k", "mope-const"), ("eql-eps10k", "eql-const"),
                         ("mope-bound-eps10k", "mope-const-bound")):
        assert changed(const, short) == {**CONSTANT_TARGET, "reward_norm": None}
    assert (by_name["mope"]["epsilon_decay_steps"], by_name["mope"]["buffer_size"]) == (None, None)
    assert by_name["mope-const-bound"]["seen_bound_margin"] == 0.1
    out = tmp_path / "bench"
    _fake_bench_run(out, "resource-gathering-v0", "eql-eps10k", 1, 50_000, 0.5)
    _fake_bench_run(out, "resource-gathering-v0", "eql-eps-greedy-unbounded", 1, 50_000, 0.5)
    assert [j.name for j in finished_runs(out)] == ["resource-gathering-v0-eql-eps-greedy-unbounded-s1",
                                                    "resource-gathering-v0-eql-eps10k-s1"]


def test_benchmark_envelope_eps_half_explores_as_long_as_mope(tmp_path: Path) -> None:
    """``envelope-eps-half`` is Envelope's example with mope's exploration schedule (half the run, at least 10k)."""
    from mope.config import epsilon_decay_steps_of
    from mope.paper.benchmark import benchmark_jobs, finished_runs

    for env_id, total in (("minecart-deterministic-v0", 100_000), ("deep-sea-treasure-v0", 20_000)):
        jobs = {j.name.rpartition(env_id + "-")[2]: j for j in
                benchmark_jobs([env_id], ["envelope", "envelope-eps-half", "mope"], [0], quick=False, steps=None)}
        assert jobs["envelope-s0"].payload["overrides"]["epsilon_decay_steps"] == 10_000
        half = jobs["envelope-eps-half-s0"]
        assert half.kind == "envelope" and half.payload["overrides"]["epsilon_decay_steps"] == epsilon_decay_steps_of(
            Config.from_dict(jobs["mope-s0"].payload)) == max(10_000, total // 2)
        assert {k: v for k, v in half.payload["overrides"].items() if jobs["envelope-s0"].payload["overrides"][k] != v
                } == ({"epsilon_decay_steps": 50_000} if total > 20_000 else {})  # DST: the example's 10k
    _fake_bench_run(tmp_path, "four-room-v0", "envelope-eps-half", 2, 50_000, 0.5)
    assert [(j.name, j.kind) for j in finished_runs(tmp_path)] == [("four-room-v0-envelope-eps-half-s2", "envelope")]


def test_committed_benchmark_runs_ran_their_methods_settings() -> None:
    """Every committed mope run trained with what its method's job sets today (epsilon's decay and the buffer
    resolved): the folder names and METHODS cannot drift apart unseen."""
    from mope.config import buffer_capacity, epsilon_decay_steps_of
    from mope.paper.benchmark import benchmark_jobs, finished_runs

    out = Path(__file__).resolve().parents[1] / "docs/results/benchmark"
    learning = [*Config.hyperparameter_names(), "eval_every", "eval_prefs"]

    def settings(data: dict) -> dict:
        c = Config.from_dict(data)
        d = c.to_dict()
        d["epsilon_decay_steps"], d["buffer_size"] = epsilon_decay_steps_of(c), buffer_capacity(c)
        return {k: d[k] for k in learning}

    checked = 0
    for job in finished_runs(out):
        if job.kind == "envelope":
            continue
        saved = json.loads((out / job.name / "config.json").read_text())
        env_id, seed = saved["env_id"], saved["seed"]
        method = job.name[len(env_id) + 1:].rpartition("-s")[0]
        [ref] = benchmark_jobs([env_id], [method], [seed], quick=False, steps=None)
        assert settings(saved) == settings(ref.payload), job.name
        checked += 1
    assert checked >= 90


def test_the_presets_and_the_robot_game_keep_the_constant_target_one_step_exploration_and_no_bound() -> None:
    """The late anneal, ez-greedy and the seen-return bound are the learner's defaults, not the presets' (their hard
    copies ignore the anneal, and their saved runs carry the older fields) nor the robot game's (its 5 paired seeds
    won 0.031 less with the anneal; ez-greedy and the bound were not measured there)."""
    from mope.config import CONSTANT_TARGET, PLAIN_EPSILON, UNBOUNDED

    kept = {**CONSTANT_TARGET, **PLAIN_EPSILON, **UNBOUNDED}
    for preset in ("paper", "envelope"):
        cfg = Config.from_dict({"preset": preset})
        assert {k: getattr(cfg, k) for k in kept} == kept
    game = Config.from_dict({"env_id": "mope/RobotConfrontationDiscrete-v0"})
    assert {k: getattr(game, k) for k in kept} == kept
    dst = Config.from_dict({"env_id": "deep-sea-treasure-v0"})
    assert (dst.target_tau_end, dst.target_tau_anneal_from, dst.epsilon_repeat_mu, dst.seen_bound_margin) == (
        1e-4, 0.5, 2.0, 0.1)


def test_the_cpu_description_names_the_kernels_torch_dispatches_to() -> None:
    """Streams differ between hosts that share a CPU name (two "AMD EPYC" hosts trained different Deep-Sea-Treasure
    streams), so a run's summary and a benchmark piece record the family, the model and torch's kernel level, not the
    name alone."""
    import platform

    import torch

    from mope.experiments.runs import _environment_info, cpu_description
    from mope.paper.benchmark import _machine

    text = cpu_description()
    assert text.endswith(f"{torch.backends.cpu.get_cpu_capability()} kernels)"), text
    if platform.system() == "Linux":
        assert "family " in text and ", model " in text, text
    assert _environment_info()["cpu"] == text and _machine(1.0, "x")["machine"].startswith(text)


def test_benchmark_report_measures_resource_gathering_against_the_exact_front() -> None:
    """The committed resource-gathering runs recorded MO-Gymnasium's optimum (0.526); the report measures them
    against the exact front's (0.571, mope.evaluation.diagnose) and says so, and each gap is that optimum minus
    the run's final EUM."""
    from mope.paper.benchmark import finished_runs, summarise

    root = Path(__file__).resolve().parents[1] / "docs/results/benchmark"
    jobs = [j for j in finished_runs(root) if j.payload["env_id"] == "resource-gathering-v0"
            and j.name.endswith(("-s0", "-s1"))]
    rg = summarise(root, jobs)["resource-gathering-v0"]
    meta = rg.pop("_meta")
    assert meta["recorded_optimal_eum"] == pytest.approx(0.5258, abs=1e-4)
    assert meta["optimal_eum"] == pytest.approx(0.5707, abs=1e-4)
    for s in rg.values():
        gaps, eums = s["values"]["eum_gap"], s["values"]["eum"]
        np.testing.assert_allclose(gaps, [meta["optimal_eum"] - e for e in eums])
    md = (root / "benchmark.md").read_text()
    assert "recorded the optimum 0.526" in md and "(95 % of the optimal 0.571)" in md
