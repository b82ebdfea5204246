"""Resumable training: a resumed run equals an uninterrupted one, step for step.

Covers: agent-level save/load mid-episode; ``mope train`` stopped by SIGINT, SIGTERM and SIGKILL, then
``mope train --resume``; the run folder's resume bookkeeping (status, config mismatch, finished runs).
"""

from __future__ import annotations

import csv
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from mope import MoPE
from mope.config import Config
from mope.errors import MopeError
from mope.experiments.runs import RunFolderError, run_status, train_run

SMALL = {"total_steps": 300, "eval_every": 100, "eval_prefs": 50, "n_omega": 8, "hidden_sizes": [32, 32],
         "learning_starts": 50, "checkpoint_every": 100, "seed": 3}
# slow enough (a few ms per step) that a signal lands mid-run, fast enough for CI: a 64x64 network (the default
# 256x256x256 made each of these tests 45 s of the suite; 1600 steps with checkpoints every 400, 30 s)
SIGNALLED = {"total_steps": 800, "eval_every": 200, "eval_prefs": 50, "n_omega": 8, "learning_starts": 100,
             "checkpoint_every": 200, "seed": 1, "hidden_sizes": [64, 64], "batch_size": 32}


def _metrics(run: Path) -> list[dict[str, str]]:
    with open(run / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        r.pop("wall_s")
        r.pop("train_s", None)
    return rows


@pytest.mark.parametrize("extra", [{}, {"return_mix": 0.0}, {"n_envs": 3, "train_freq": 2},
                                   {"n_envs": 4, "n_step": 3, "gradient_steps": 2},
                                   {"n_envs": 2, "seen_bound_margin": 0.0, "epsilon_repeat_mu": None},
                                   {"n_envs": 4, "epsilon_repeat_mu": 1.5}],
                         ids=["defaults", "no-return-mix", "three-envs", "four-envs-n-step", "seen-bound", "ez-greedy"])
def test_agent_save_load_mid_episode_continues_identically(tmp_path, extra):
    cfg = Config.for_algo("mope", total_steps=400, learning_starts=50, n_omega=8, hidden_sizes=[32, 32], seed=5,
                          **extra)
    n = cfg.n_envs
    ref = MoPE("deep-sea-treasure-v0", cfg)
    ref.train(400)
    a = MoPE("deep-sea-treasure-v0", cfg)
    a.train(237 if n == 1 else 240)
    assert sum(bool(ep.actions) for ep in a._episodes) >= min(n, 2), "the test must checkpoint inside episodes"
    a.save(tmp_path / "mid.pt", include_buffer=True)
    b = MoPE.load(tmp_path / "mid.pt")
    for ep_a, ep_b in zip(a._episodes, b._episodes, strict=True):
        np.testing.assert_array_equal(np.asarray(ep_b.obs), np.asarray(ep_a.obs))
        assert (ep_a.seed, ep_a.actions, ep_a.slots, ep_a.greedy, ep_a.repeat) == (ep_b.seed, ep_b.actions,
                                                                                   ep_b.slots, ep_b.greedy, ep_b.repeat)
    if extra.get("epsilon_repeat_mu"):
        assert any(ep.repeat for ep in a._episodes), "the test must checkpoint inside a repeated random action"
    b.train(400 - a.global_step)
    assert b.global_step == ref.global_step == -(-400 // n) * n and b.episodes == ref.episodes  # whole steps of n
    assert b.episodes_started == ref.episodes_started
    for p_ref, p_b in zip(ref.q_net.parameters(), b.q_net.parameters(), strict=True):
        assert np.array_equal(p_ref.detach().numpy(), p_b.detach().numpy())
    np.testing.assert_array_equal(ref.pref_sampler.counts, b.pref_sampler.counts)
    if cfg.seen_bound_margin is not None:  # the returns seen, from episodes that ended on either side of the checkpoint
        np.testing.assert_array_equal(ref.seen_returns, b.seen_returns)
        np.testing.assert_array_equal(ref._q_high_t.numpy(), b._q_high_t.numpy())
    if extra.get("return_mix") != 0.0:  # the greedy-tail returns of the episodes that spanned the checkpoint too
        np.testing.assert_array_equal(ref.buffer.return_steps, b.buffer.return_steps)
        np.testing.assert_array_equal(ref.buffer.returns, b.buffer.returns)


def test_the_game_with_demonstrations_continues_identically_after_save_and_load(tmp_path):
    """The robot game's recipe (4 envs, scripted demonstrations, pre-training) resumed from a whole-state checkpoint
    is the uninterrupted run bit for bit: what ``scripts/game_study.py --resume`` forks arms on."""
    from mope import make_agent
    from mope.envs import confrontation as C

    kw = {"seed": 3, "total_steps": 800, "demo_episodes": 2, "demo_pretrain_steps": 20, "learning_starts": 100,
          "buffer_size": 2_000, "hidden_sizes": [32, 32]}
    ref = make_agent("mope", C.DISCRETE_ID, **kw)
    ref.train(800)
    a = make_agent("mope", C.DISCRETE_ID, **kw)
    a.train(400)
    a.save(tmp_path / "mid.pt", include_buffer=True)
    b = MoPE.load(tmp_path / "mid.pt")
    b.train(800 - b.global_step)
    assert b.global_step == ref.global_step == 800
    for p_ref, p_b in zip(ref.q_net.parameters(), b.q_net.parameters(), strict=True):
        assert np.array_equal(p_ref.detach().numpy(), p_b.detach().numpy())


def test_train_run_resume_bookkeeping(tmp_path):
    cfg = Config.for_algo("eql", **SMALL)
    out = tmp_path / "run"
    assert run_status(out) == "new"
    ref = train_run(cfg, tmp_path / "ref", progress=False)
    # a run that stopped after its step-200 checkpoint: fake it from a finished run by removing its end
    train_run(cfg, out, progress=False)
    (out / "summary.json").unlink()
    (out / "checkpoints" / "final.pt").unlink()
    full = MoPE.load(out / "checkpoints" / "resume.pt")
    assert full.global_step == 300 and run_status(out) == "resumable"
    # resuming from step 300 (= total) only finishes the folder
    res = train_run(cfg, out, progress=False, resume=True)
    assert run_status(out) == "finished" and res.agent.global_step == 300
    assert _metrics(out) == _metrics(tmp_path / "ref")
    assert res.final["cr"] == ref.final["cr"]
    # a finished run is returned as it is
    again = train_run(cfg, out, progress=False, resume=True)
    assert again.final["cr"] == ref.final["cr"] and again.agent.global_step == 300
    # another config is refused, naming the field
    with pytest.raises(RunFolderError, match="total_steps"):
        train_run(cfg.replace(total_steps=500), out, progress=False, resume=True)
    # without --resume, an existing run is not clobbered
    with pytest.raises(MopeError, match="already holds a run"):
        train_run(cfg, out, progress=False)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ref") / "run"
    train_run(Config.for_algo("mope", **SIGNALLED), out, progress=False)
    return out


def _train_cmd(out: Path) -> list[str]:
    sets = [f"--set={k}={','.join(map(str, v)) if isinstance(v, list) else v}" for k, v in SIGNALLED.items()
            if k not in ("total_steps", "seed")]
    return [sys.executable, "-m", "mope.cli", "train", "--algo", "mope", "--steps", str(SIGNALLED["total_steps"]),
            "--seed", str(SIGNALLED["seed"]), "--out", str(out), "--no-progress", *sets]


def _wait_for(path: Path, proc: subprocess.Popen, timeout: float = 300) -> None:
    deadline = time.time() + timeout
    while not path.exists():
        assert proc.poll() is None, "training ended before the signal could be sent"
        assert time.time() < deadline, f"{path} did not appear"
        time.sleep(0.05)


@pytest.mark.slow
@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM", "SIGKILL"])
def test_killed_run_resumes_to_the_uninterrupted_result(tmp_path, uninterrupted, signame):
    out = tmp_path / "run"
    proc = subprocess.Popen(_train_cmd(out), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # SIGKILL right after the first periodic checkpoint; SIGINT/SIGTERM a little later, at an arbitrary step
    _wait_for(out / "checkpoints" / "step_200.pt", proc)
    if signame != "SIGKILL":
        time.sleep(0.4)  # about 100 steps here; 600 steps remain, for a machine several times faster
    proc.send_signal(getattr(signal, signame))
    _, err = proc.communicate(timeout=120)
    if signame == "SIGKILL":
        assert proc.returncode == -signal.SIGKILL
    else:
        assert proc.returncode == 130, err
        assert f"mope train --resume {out}" in err and "Traceback" not in err
    assert run_status(out) == "resumable"
    stopped_at = MoPE.load(out / "checkpoints" / "resume.pt").global_step
    assert 200 <= stopped_at < SIGNALLED["total_steps"]

    res = subprocess.run([sys.executable, "-m", "mope.cli", "train", "--resume", str(out), "--no-progress"],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert run_status(out) == "finished"
    assert _metrics(out) == _metrics(uninterrupted)
    final_ref = MoPE.load(uninterrupted / "checkpoints" / "final.pt")
    final = MoPE.load(out / "checkpoints" / "final.pt")
    for p_ref, p in zip(final_ref.q_net.parameters(), final.q_net.parameters(), strict=True):
        assert np.array_equal(p_ref.detach().numpy(), p.detach().numpy())


def test_resume_cli_errors(tmp_path):
    res = subprocess.run([sys.executable, "-m", "mope.cli", "train", "--resume", str(tmp_path / "nothing")],
                         capture_output=True, text=True)
    assert res.returncode == 2 and "not a mope run folder" in res.stderr and "Traceback" not in res.stderr
    res = subprocess.run([sys.executable, "-m", "mope.cli", "train", "--resume", str(tmp_path), "--steps", "5"],
                         capture_output=True, text=True)
    assert res.returncode == 2 and "drop --steps" in res.stderr
    res = subprocess.run([sys.executable, "-m", "mope.cli", "train", "--resume", str(tmp_path), "--n-omega", "3",
                          "--algo", "eql"], capture_output=True, text=True)
    assert res.returncode == 2 and "drop --algo, --n-omega" in res.stderr


def test_divergence_names_step_and_quantity_and_keeps_the_last_good_checkpoint(tmp_path, monkeypatch):
    import torch

    import mope.agent.agent as agent_module

    cfg = Config.for_algo("eql", **{**SMALL, "total_steps": 400, "checkpoint_every": 100})
    original = agent_module.MoPE.update

    def poisoned(self):
        if self.global_step == 250:  # after the step-200 checkpoint, a weight turns NaN
            with torch.no_grad():
                self.q_net.net[0].weight.fill_(float("nan"))
        return original(self)

    monkeypatch.setattr(agent_module.MoPE, "update", poisoned)
    out = tmp_path / "run"
    with pytest.raises(agent_module.TrainingDivergedError) as err:
        train_run(cfg, out, progress=False)
    msg = str(err.value)
    assert "step 250" in msg and "Q-value is nan" in msg and "resume.pt" in msg
    good = MoPE.load(out / "checkpoints" / "resume.pt")
    assert good.global_step == 200
    assert all(torch.isfinite(p).all() for p in good.q_net.parameters())
    assert run_status(out) == "resumable" and not (out / "summary.json").exists()


def test_overwrite_leaves_nothing_of_the_old_run_and_stale_resume_state_is_refused(tmp_path):
    from mope.experiments.runs import prepare_out_dir

    cfg = Config.for_algo("eql", **SMALL)
    out = tmp_path / "run"
    train_run(cfg, out, progress=False)
    prepare_out_dir(out, overwrite=True)
    left = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    assert left == [], left
    assert run_status(out) == "new"
    # a resume.pt written by another config is refused, not silently continued
    train_run(cfg, out, progress=False)
    (out / "summary.json").unlink()
    other = cfg.replace(learning_rate=5e-4)
    other.save(out / "config.json")
    with pytest.raises(RunFolderError, match="learning_rate"):
        train_run(other, out, progress=False, resume=True)


def test_resume_at_the_last_step_still_writes_the_final_solutions(tmp_path):
    cfg = Config.for_algo("eql", **SMALL)
    out = tmp_path / "run"
    ref = train_run(cfg, out, progress=False)
    solutions_ref = (out / "solutions.csv").read_text()
    for name in ("summary.json", "solutions.csv", "checkpoints/final.pt"):
        (out / name).unlink()
    res = train_run(cfg, out, progress=False, resume=True)
    assert (out / "solutions.csv").read_text() == solutions_ref
    assert res.final["step"] == 300 and isinstance(res.final["step"], int) and res.final["cr"] == ref.final["cr"]
