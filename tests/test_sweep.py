"""`mope sweep`: spec validation, trial naming, the local and Ray backends, skip / resume / failure on re-run."""

from __future__ import annotations

import csv
import json
import shutil
import signal
from pathlib import Path

import pytest
import yaml

from mope.agent.agent import MoPE
from mope.config import Config
from mope.errors import MopeError
from mope.experiments.jobs import JobError, run_job_remote, unpack_job
from mope.experiments.runs import train_run
from mope.experiments.sweep import (
    SweepError,
    apply_overrides,
    expand,
    load_spec,
    parse_set,
    parse_spec,
    run_sweep,
    trial_name,
)

TINY = {"env_id": "deep-sea-treasure-v0", "total_steps": 300, "eval_every": 100, "eval_prefs": 50, "n_omega": 4,
        "batch_size": 8, "learning_starts": 50, "hidden_sizes": [16, 16], "disc_hidden": [16],
        "checkpoint_every": 100}
SPEC = {"name": "tiny", "base": TINY, "grid": {"algo": ["eql", "mope"]}, "seeds": 2}
NAMES = ["deep-sea-treasure-v0-eql-s0", "deep-sea-treasure-v0-mope-s0", "deep-sea-treasure-v0-eql-s1",
         "deep-sea-treasure-v0-mope-s1"]


def metrics_without_wall(folder: Path) -> list[dict[str, str]]:
    with open(folder / "metrics.csv") as f:
        return [{k: v for k, v in row.items() if k not in ("wall_s", "train_s")} for row in csv.DictReader(f)]


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("local")
    results = run_sweep(parse_spec(SPEC), out, workers=2, progress=False)
    assert [(r.name, r.status, r.action) for r in results] == [(n, "finished", "trained") for n in NAMES]
    return out


# ---------------------------------------------------------------------------------------------------------------
# spec
# ---------------------------------------------------------------------------------------------------------------
def test_spec_expands_seed_major_with_readable_names(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump({"base": {"total_steps": 500}, "grid": {"algo": ["eql", "mope"],
                                    "sigma_omega": [0.02, 0.04]}, "seed": [3, 7]}))
    spec = load_spec(path)
    assert spec.name == "s" and spec.seeds == [3, 7]
    trials = expand(spec)
    assert len(trials) == 8
    assert trials[0].name == "deep-sea-treasure-v0-eql-sigma_omega=0.02-s3"
    assert trials[-1].name == "deep-sea-treasure-v0-mope-sigma_omega=0.04-s7"
    assert [t.config.seed for t in trials] == [3] * 4 + [7] * 4
    fifth = trials[5].config
    assert fifth.algo == "eql" and fifth.sigma_omega == 0.04 and fifth.total_steps == 500
    cfg = Config.for_algo("mope", hidden_sizes=(64, 64), seed=2)
    assert trial_name(cfg, {"hidden_sizes": [64, 64], "double_q": False}) == \
        "deep-sea-treasure-v0-mope-hidden_sizes=64,64-double_q=false-s2"


@pytest.mark.parametrize(("spec", "message"), [
    ({"grdi": {"algo": ["eql"]}}, "unknown spec key 'grdi' (did you mean 'grid'?)"),
    ({"base": {"totl_steps": 5}}, "unknown config key 'totl_steps' in base (did you mean 'total_steps'?)"),
    ({"grid": {"sigma_omgea": [0.1]}}, "unknown config key 'sigma_omgea' in grid (did you mean 'sigma_omega'?)"),
    ({"seeds": 2, "seed": [0, 1]}, "seeds are given twice (seeds, seed); keep one"),
    ({"seeds": 0}, "seeds=0 is out of range"),
    ({"seeds": [1, 1]}, "seeds=[1, 1] lists a seed twice"),
    ({"grid": {"algo": []}}, "grid.algo is an empty list"),
    ({"grid": {"hidden_sizes": [64, 64]}}, "grid.hidden_sizes=[64, 64] must be a list of lists"),
    ({"base": {"gamma": 0.9}, "grid": {"gamma": [0.9]}}, "'gamma' is both in base and in grid"),
    ({"grid": {"algo": ["eql", "mopee"]}},
     "trial (algo=mopee, seed=0): unknown algorithm 'mopee' (did you mean 'mope'?)"),
    ({"grid": {"batch_size": [8, 0]}}, "trial (batch_size=0, seed=0): batch_size=0 is out of range"),
    ({"name": "a/b"}, "name='a/b' must be a folder-safe name"),
    ([1, 2], "a sweep spec must be a mapping"),
])
def test_bad_specs_name_the_bad_key(spec: object, message: str) -> None:
    with pytest.raises(SweepError) as err:
        expand(parse_spec(spec))
    assert message in str(err.value)


def test_nothing_is_launched_for_a_bad_trial_or_environment(tmp_path: Path) -> None:
    base = {k: v for k, v in TINY.items() if k != "env_id"}
    bad_env = {"base": base, "grid": {"env_id": ["deep-sea-treasure-v0", "deep-sea-treasur-v0"]}}
    with pytest.raises(MopeError, match="unknown environment 'deep-sea-treasur-v0' \\(did you mean"):
        run_sweep(parse_spec(bad_env), tmp_path / "a", progress=False)
    with pytest.raises(SweepError, match="trial \\(learning_rate=-1, seed=0\\): learning_rate=-1 is out of range"):
        run_sweep(parse_spec({"base": TINY, "grid": {"learning_rate": [0.001, -1]}, "seeds": 2}), tmp_path / "b",
                  progress=False)
    with pytest.raises(SweepError, match="unknown backend 'rey' \\(did you mean 'ray'\\?\\)"):
        run_sweep(parse_spec(SPEC), tmp_path / "c", backend="rey")
    with pytest.raises(SweepError, match="--address auto needs --backend ray"):
        run_sweep(parse_spec(SPEC), tmp_path / "c", address="auto")
    with pytest.raises(SweepError, match="workers=0 is out of range"):
        run_sweep(parse_spec(SPEC), tmp_path / "c", workers=0)
    with pytest.raises(SweepError, match="sweep spec '.*missing.yaml' does not exist"):
        load_spec(tmp_path / "missing.yaml")
    (tmp_path / "broken.yaml").write_text("grid: [unclosed")
    with pytest.raises(SweepError, match="could not be parsed"):
        load_spec(tmp_path / "broken.yaml")
    assert not any((tmp_path / d).exists() for d in "abc")


@pytest.mark.parametrize(("text", "seeds"), [("3", [0, 1, 2]), ("5-9", [5, 6, 7, 8, 9]), ("0,5,7", [0, 5, 7]),
                                            ("4-4", [4]), (2, [0, 1])])
def test_seeds_option_takes_a_count_a_range_or_a_list(text, seeds) -> None:
    assert apply_overrides(parse_spec(SPEC), seeds=text).seeds == seeds


@pytest.mark.parametrize(("text", "message"), [
    ("9-5", "--seeds='9-5': the range ends before it starts"),
    ("five", "--seeds='five' is not a count \\(5\\), a range \\(5-9\\) or a list of seeds \\(0,5,7\\)"),
    ("5-", "--seeds='5-' is not a count"),
    ("0", "--seeds=0 is out of range"),
    ("-3", "--seeds=-3 is out of range"),
    ("1,1", "--seeds=\\[1, 1\\] lists a seed twice"),
    ("1,-2", "is not a seed count or a non-empty list of seeds >= 0"),
])
def test_bad_seeds_option_names_the_value(text, message) -> None:
    with pytest.raises(SweepError, match=message):
        apply_overrides(parse_spec(SPEC), seeds=text)


def test_overrides_pin_grid_axes_and_seeds() -> None:
    spec = apply_overrides(parse_spec(SPEC), parse_set(["algo=mope", "total_steps=200", "hidden_sizes=[8, 8]"]),
                           seeds=3)
    assert spec.grid == {} and spec.seeds == [0, 1, 2]
    trials = expand(spec)
    assert [t.name for t in trials] == [f"deep-sea-treasure-v0-mope-s{s}" for s in range(3)]
    assert trials[0].config.total_steps == 200 and trials[0].config.hidden_sizes == (8, 8)
    with pytest.raises(SweepError, match="unknown config key 'totl_steps' \\(did you mean 'total_steps'\\?\\)"):
        apply_overrides(parse_spec(SPEC), parse_set(["totl_steps=3"]))
    with pytest.raises(SweepError, match="--set 'oops' is not KEY=VALUE"):
        parse_set(["oops"])


# ---------------------------------------------------------------------------------------------------------------
# backends
# ---------------------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_local_and_ray_backends_agree(local_sweep: Path, tmp_path: Path) -> None:
    ray = pytest.importorskip("ray")
    # one Ray worker: beside the suite's other pytest worker, two Ray workers starved (262 s in a .ci/run beside one
    # training, where this test alone takes 37 s); with one, 19 s against 31 s beside a busy core
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        results = run_sweep(parse_spec(SPEC), tmp_path, backend="ray", progress=False)
    finally:
        ray.shutdown()
    assert [(r.name, r.status, r.action) for r in results] == [(n, "finished", "trained") for n in NAMES]
    for name in NAMES:
        local_rows, ray_rows = metrics_without_wall(local_sweep / name), metrics_without_wall(tmp_path / name)
        assert [r["step"] for r in local_rows] == ["100", "200", "300"]
        assert local_rows == ray_rows, name
        assert (local_sweep / name / "solutions.csv").read_text() == (tmp_path / name / "solutions.csv").read_text()
    # the two algorithms differ, so agreement is not a coincidence of identical runs
    assert metrics_without_wall(local_sweep / NAMES[0]) != metrics_without_wall(local_sweep / NAMES[1])
    doc = json.loads((tmp_path / "sweep.json").read_text())
    assert doc["backend"] == "ray" and doc["swept"] == ["algo", "seed"]
    assert [t["status"] for t in doc["trials"]] == ["finished"] * 4


@pytest.mark.slow
def test_rerun_skips_finished_resumes_interrupted_and_records_failures(local_sweep: Path, tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    spec = apply_overrides(parse_spec(SPEC), {"algo": "eql"}, seeds=3)
    trials = expand(spec)
    # seed 0: finished earlier -> skipped
    shutil.copytree(local_sweep / trials[0].name, tmp_path / trials[0].name)
    # seed 1: interrupted at step 150 by SIGINT (as Ctrl-C would) -> resumed from checkpoints/resume.pt
    import mope.experiments.runs as experiments
    from mope.agent.runner import Callback

    original_train = experiments.train

    class SigintAt150(Callback):
        def on_step(self, agent: MoPE, stats: object) -> bool:
            if agent.global_step == 150:
                signal.raise_signal(signal.SIGINT)
            return True

    def interrupted_train(agent: MoPE, steps: int, callbacks: list) -> object:
        return original_train(agent, steps, [SigintAt150(), *callbacks])

    monkeypatch.setattr(experiments, "train", interrupted_train)
    with pytest.raises(KeyboardInterrupt):
        train_run(trials[1].config, tmp_path / trials[1].name, progress=False)
    monkeypatch.setattr(experiments, "train", original_train)
    assert (tmp_path / trials[1].name / "checkpoints" / "resume.pt").is_file()
    assert not (tmp_path / trials[1].name / "summary.json").exists()
    # seed 2: its folder cannot hold checkpoints -> failed, recorded, the others go on
    (tmp_path / trials[2].name).mkdir()
    (tmp_path / trials[2].name / "checkpoints").write_text("not a folder")

    results = run_sweep(spec, tmp_path, workers=2, progress=False)
    assert [(r.status, r.action) for r in results] == [("finished", "skipped"), ("finished", "resumed"),
                                                      ("failed", "failed")]
    assert "RunFolderError" in results[2].error
    assert "RunFolderError" in (tmp_path / trials[2].name / "error.txt").read_text()
    # the resumed run matches the uninterrupted one step for step
    assert metrics_without_wall(tmp_path / trials[1].name) == metrics_without_wall(local_sweep / trials[1].name)
    doc = json.loads((tmp_path / "sweep.json").read_text())
    assert [t["status"] for t in doc["trials"]] == ["finished", "finished", "failed"]
    assert doc["trials"][2]["error"].startswith("RunFolderError")

    # how often a run saved or logged does not change it: the finished folders are the same runs
    resaved = apply_overrides(spec, {"checkpoint_every": 7, "log_every": 3})
    assert [r.action for r in run_sweep(resaved, tmp_path, progress=False)][:2] == ["skipped", "skipped"]
    # a spec changed since: the finished folder of another config is refused before anything runs
    changed = apply_overrides(spec, {"total_steps": 400})
    with pytest.raises(SweepError, match="holds a run of another config: total_steps \\(300 there, 400 now\\)"):
        run_sweep(changed, tmp_path, progress=False)


def test_a_ray_node_without_the_sweep_folder_sends_the_trial_back(tmp_path: Path) -> None:
    # a worker node that does not see <out>/sweep.json trains into a temporary folder and returns it packed
    config = Config.for_algo("eql", **{**TINY, "total_steps": 60, "eval_every": 0, "learning_starts": 20})
    rec = run_job_remote("t-s0", "train", config.to_dict(), str(tmp_path / "elsewhere" / "t-s0"))
    assert rec["status"] == "finished" and not (tmp_path / "elsewhere").exists()
    out, archive = tmp_path / "sweep", rec["archive"]
    unpack_job(rec, out)
    assert "archive" not in rec
    assert {p.name for p in (out / "t-s0").iterdir()} >= {"config.json", "metrics.csv", "summary.json", "solutions.csv"}
    assert (out / "t-s0" / "checkpoints" / "final.pt").is_file()
    assert not (out / "t-s0" / "checkpoints" / "resume.pt").exists()
    with pytest.raises(JobError, match="holds files outside its folder"):
        unpack_job({"name": "other", "archive": archive}, out)


def test_arms_are_named_one_off_changes_crossed_with_the_grid() -> None:
    spec = parse_spec({"name": "study", "base": {"total_steps": 100}, "grid": {"algo": ["eql", "mope"]},
                       "arms": {"default": {}, "paper": {"preset": "paper"}, "lr": {"learning_rate": 1e-4}},
                       "seeds": 2})
    trials = expand(spec)
    assert len(trials) == 2 * 2 * 3
    assert trials[0].name == "deep-sea-treasure-v0-eql-default-s0"
    by_name = {t.name: t for t in trials}
    paper = by_name["deep-sea-treasure-v0-mope-paper-s1"]
    assert paper.params == {"algo": "mope", "arm": "paper", "seed": 1}
    assert paper.config.hidden_sizes == (64, 128, 128, 64) and paper.config.total_steps == 100
    assert by_name["deep-sea-treasure-v0-eql-lr-s0"].config.learning_rate == 1e-4
    assert apply_overrides(spec, seeds=1).arms == spec.arms  # --seeds / --set keep the arms
    with pytest.raises(SweepError, match="'algo' is both a grid axis and set by arms.x"):
        parse_spec({"grid": {"algo": ["eql"]}, "arms": {"x": {"algo": "mope"}}})
    with pytest.raises(SweepError, match="unknown config key 'lr' in arms.x"):
        parse_spec({"arms": {"x": {"lr": 1}}})
    with pytest.raises(SweepError, match="arm name 'a b' must be folder-safe"):
        parse_spec({"arms": {"a b": {}}})


@pytest.mark.slow
def test_a_killed_sweep_stops_its_workers_and_resumes(tmp_path: Path) -> None:
    import os
    import subprocess
    import sys
    import time

    spec = {**SPEC, "base": {**TINY, "total_steps": 4000, "eval_every": 0, "checkpoint_every": 200}, "seeds": 1,
            "grid": {"algo": ["eql"]}}
    (tmp_path / "spec.yaml").write_text(yaml.safe_dump(spec))
    out = tmp_path / "sweep"
    cmd = [sys.executable, "-m", "mope.cli", "sweep", str(tmp_path / "spec.yaml"), "--out", str(out), "--workers", "1",
           "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    trial = out / "deep-sea-treasure-v0-eql-s0"
    deadline = time.monotonic() + 300
    while not (trial / "checkpoints" / "resume.pt").is_file() and time.monotonic() < deadline:
        time.sleep(0.5)
    worker = json.loads((trial / ".mope.lock").read_text())["pid"]
    time.sleep(2)  # let it train past its first periodic checkpoint
    proc.terminate()  # SIGTERM to the sweep only, as `kill` would
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130 and "run the same command again to resume" in err and "Traceback" not in err
    with pytest.raises(ProcessLookupError):
        os.kill(worker, 0)  # the worker is gone, not left training
    assert not (trial / "summary.json").exists() and not (trial / ".mope.lock").exists()
    # the worker saved its state when interrupted (after the last periodic step_N.pt), not only periodically
    newest_periodic = max((trial / "checkpoints").glob("step_*.pt"), key=lambda p: p.stat().st_mtime)
    assert (trial / "checkpoints" / "resume.pt").stat().st_mtime > newest_periodic.stat().st_mtime
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0 and "resumed" in res.stdout, res.stderr


def test_a_run_saved_before_reward_norm_is_reused_where_the_norm_does_not_act(tmp_path: Path) -> None:
    """A finished run whose config.json predates ``reward_norm`` (read as None) is the same run as today's where
    the environment's rewards never exceed the norm (Deep-Sea-Treasure: exactly the same factor, 1), so a sweep
    skips it; on the mirrored map (rewards up to 124) the norm acts, and the old folder is refused."""
    from mope.agent.agent import without_inert_reward_norm

    spec = parse_spec({"name": "old", "base": {**TINY, "total_steps": 60, "eval_every": 60, "reward_norm": None},
                       "grid": {"algo": ["eql"]}, "seeds": 1})
    run_sweep(spec, tmp_path, progress=False)
    cfg_path = tmp_path / "deep-sea-treasure-v0-eql-s0" / "config.json"
    saved = json.loads(cfg_path.read_text())
    del saved["reward_norm"]  # as written before the setting existed
    cfg_path.write_text(json.dumps(saved))
    today = apply_overrides(spec, {"reward_norm": 25.0})
    assert [(r.status, r.action) for r in run_sweep(today, tmp_path, progress=False)] == [("finished", "skipped")]

    mirrored = Config(env_id="deep-sea-treasure-mirrored-v0", reward_norm=25.0).to_dict()
    before = Config.from_dict({k: v for k, v in mirrored.items() if k != "reward_norm"}).to_dict()
    assert before["reward_norm"] is None
    assert without_inert_reward_norm(mirrored)["reward_norm"] == 25.0
    assert without_inert_reward_norm(before) != without_inert_reward_norm(mirrored)
    dst = Config(env_id="deep-sea-treasure-v0", reward_norm=25.0).to_dict()
    assert without_inert_reward_norm(dst)["reward_norm"] is None
