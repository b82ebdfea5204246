"""The ``mope`` command line: train, eval, act, sweep, report, reproduce, envs.

Every bad input ends in one line ``error: ...`` on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import functools
import json
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer

from mope.config import ALGOS, ENV_DEFAULTS, PRESETS, Config, check_algo, parse_overrides, read_config_file
from mope.errors import ConfigError, MopeError, RunFolderError, is_disk_full, one_line

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Multi-objective RL with Preference Exploration (MoPE) and Envelope Q-learning.")


def _fail(message: str) -> None:
    typer.echo(f"error: {one_line(message)}", err=True)
    raise typer.Exit(2)


RESUME_HINT = "run the same command again to resume"


def handles_errors(interrupted: str | None = None) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """The one error handling of the commands: a :class:`MopeError` is one ``error:`` line and exit code 2; with
    ``interrupted``, Ctrl-C prints ``interrupted; <interrupted>`` and exits with 130."""
    def wrap(command: Callable[..., None]) -> Callable[..., None]:
        @functools.wraps(command)
        def run(*args: Any, **kwargs: Any) -> None:
            try:
                command(*args, **kwargs)
            except MopeError as exc:
                _fail(str(exc))
            except KeyboardInterrupt:
                if interrupted is None:
                    raise
                typer.echo(f"\ninterrupted; {interrupted}", err=True)
                raise typer.Exit(130) from None
        return run
    return wrap


def quiet_media() -> None:
    """Keep pygame from probing sound cards and displays (:func:`mope.evaluation.video.quiet_media`)
    before it is imported."""
    from mope.evaluation.video import quiet_media as quiet

    quiet()


_D = Config()


def _default(name: str) -> str:
    value = _D.to_dict()[name]
    return ",".join(map(str, value)) if isinstance(value, list) else str(value)


def _train_help() -> str:
    lines = ["Train an agent, evaluating CR/HV/EUM as it goes; writes a run folder.", "",
             "Per-environment defaults, used for every setting not given (--preset paper skips them):"]
    lines += [f"{env_id}: " + ", ".join(f"{k}={v}" for k, v in d.items()) for env_id, d in ENV_DEFAULTS.items()]
    return "\n\n".join(lines[:2]) + "\n\n" + "\n\n".join(lines[2:])


@app.command(help=_train_help())
@handles_errors()
def train(
    env: Annotated[str | None, typer.Option(help=f"Environment id \\[default: {_default('env_id')}]")] = None,
    algo: Annotated[str | None, typer.Option(help=f"Variant: {', '.join(ALGOS)} \\[default: mope]")] = None,
    steps: Annotated[int | None, typer.Option(help=f"Environment steps \\[default: {_default('total_steps')}]")] = None,
    seed: Annotated[int | None, typer.Option(help=f"Random seed \\[default: {_default('seed')}]")] = None,
    out: Annotated[Path | None, typer.Option(help="Run folder \\[default: runs/<env>-<algo>-s<seed>]")] = None,
    eval_every: Annotated[int | None, typer.Option(
        help=f"Evaluate every N steps, 0: only at the end \\[default: {_default('eval_every')}]")] = None,
    eval_prefs: Annotated[int | None, typer.Option(
        help=f"Preferences per evaluation (paper: 2000) \\[default: {_default('eval_prefs')}]")] = None,
    n_omega: Annotated[int | None, typer.Option(
        help=f"Relabeled preferences per transition, N_omega \\[default: {_default('n_omega')}]")] = None,
    sigma_omega: Annotated[float | None, typer.Option(
        help=f"Relabeling radius, sigma_omega \\[default: {_default('sigma_omega')}]")] = None,
    mi_alpha: Annotated[float | None, typer.Option(
        help=f"Weight alpha of the MI priority term (eq. 7) \\[default: {_default('mi_alpha')}]")] = None,
    n_intervals: Annotated[int | None, typer.Option(
        help=f"Preference intervals N_I for PE \\[default: {_default('n_intervals')}]")] = None,
    hidden: Annotated[str | None, typer.Option(
        help=f"Q-network hidden sizes \\[default: {_default('hidden_sizes')}]")] = None,
    device: Annotated[str | None, typer.Option(help=f"cpu, cuda or auto \\[default: {_default('device')}]")] = None,
    preset: Annotated[str | None, typer.Option(
        help=f"Named defaults: {', '.join(PRESETS)} (paper: the paper's settings) \\[default: mope]")] = None,
    config: Annotated[Path | None, typer.Option(help="JSON/YAML config file; flags override it.")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Any config field, one or several: --set batch_size=64 gamma=0.9.")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing run in --out.")] = False,
    resume: Annotated[Path | None, typer.Option(
        help="Continue the run in this folder from its last checkpoint (a run killed before its first "
             "checkpoint starts over with its saved config).", metavar="RUN_DIR")] = None,
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
) -> None:
    """Train an agent, evaluating CR/HV/EUM as it goes; writes a run folder."""
    run_dir = resume
    try:
        if resume is not None:
            given = {"env": env, "algo": algo, "steps": steps, "seed": seed, "out": out, "config": config, "set": set_,
                     "eval-every": eval_every, "eval-prefs": eval_prefs, "n-omega": n_omega, "sigma-omega": sigma_omega,
                     "mi-alpha": mi_alpha, "n-intervals": n_intervals, "hidden": hidden, "preset": preset}
            _resume(resume, [f"--{k}" for k, v in given.items() if v is not None and v is not False and v != []],
                    device, progress, overwrite)
            return
        flags = {"env_id": env, "total_steps": steps, "seed": seed, "eval_every": eval_every,
                 "eval_prefs": eval_prefs, "n_omega": n_omega, "sigma_omega": sigma_omega, "mi_alpha": mi_alpha,
                 "n_intervals": n_intervals, "device": device,
                 "hidden_sizes": _int_list("--hidden", hidden) if hidden is not None else None}
        cfg = _config_from_cli(config, algo, flags, set_ or [], preset)
        run_dir = out or Path("runs") / f"{cfg.env_id}-{cfg.algo}-s{cfg.seed}"
        _check_env(cfg.env_id)
        from mope.experiments.runs import train_run  # torch only once the settings are checked: bad input is fast

        result = train_run(cfg, run_dir, progress=progress, overwrite=overwrite)
    except KeyboardInterrupt:
        _interrupted(run_dir)
    _print_final(cfg, result)


def _interrupted(run_dir: Path | None) -> None:
    """What a Ctrl-C of ``mope train`` leaves, and how to go on; exit code 130."""
    if run_dir is not None and (Path(run_dir) / "checkpoints" / "resume.pt").is_file():
        typer.echo(f"\ninterrupted; the training state is saved in {run_dir}/checkpoints/resume.pt\n"
                   f"continue with: mope train --resume {run_dir}", err=True)
    else:
        typer.echo("\ninterrupted before the run's first checkpoint; nothing of it was kept", err=True)
    raise typer.Exit(130) from None


def _int_list(flag: str, text: str) -> list[int]:
    try:
        return [int(x) for x in text.split(",")]
    except ValueError:
        raise ConfigError(f"{flag} '{text}' is not a comma-separated list of integers") from None


def _check_env(env_id: str) -> Any:
    """Refuse an unknown environment, or one whose spaces EQL/MoPE cannot learn, before torch is imported; returns
    its :class:`mope.envs.EnvSpec`."""
    from mope.envs import check_env_fits, make_env

    env = make_env(env_id)
    try:
        return check_env_fits(env, env_id)
    finally:
        env.close()


def _check_pref_of_run(path: Path, pref: str) -> None:
    """Refuse a bad ``--pref`` for a run folder before torch is imported: its length comes from the environment
    of the folder's config.json. A checkpoint file is checked once it is loaded (the only place its env is named)."""
    if not (path.is_dir() and (path / "config.json").is_file()):
        return
    from mope.preferences import validate_preference

    try:
        m = _check_env(Config.load(path / "config.json").env_id).n_objectives
    except Exception:  # noqa: BLE001 - only an early check: whatever is wrong with the folder, the loader names it
        return
    validate_preference(pref, m)


def _config_from_cli(config_file: Path | None, algo: str | None, flags: dict[str, Any], sets: list[str],
                     preset: str | None = None) -> Config:
    """Preset, then config file, then flags, then ``--set``; ``--algo`` (or the file's variant, else mope) sets the
    variant."""
    settings: dict[str, Any] = dict(read_config_file(config_file)) if config_file else {}
    file_algo = settings.pop("algo", None)
    if preset is not None:
        settings["preset"] = preset
    settings.update({k: v for k, v in flags.items() if v is not None})
    settings.update(parse_overrides(sets))
    variant = check_algo(algo or file_algo or ("mope" if not config_file else
                                                Config.from_dict(settings).algo))
    for key in ("experience_exploration", "preference_exploration"):
        settings.pop(key, None)
    return Config.for_algo(variant, **settings)


def _resume(run_dir: Path, given: list[str], device: str | None, progress: bool, overwrite: bool = False) -> None:
    """``mope train --resume RUN_DIR``: continue from resume.pt, or start over a run that has none yet; with
    ``--overwrite``, start the run over with its saved config (its old results stay until the new run's first
    checkpoint)."""
    if given:
        raise ConfigError(f"--resume continues a run with its saved config; drop {', '.join(given)}")
    if run_dir.is_file():
        raise RunFolderError(f"--resume '{run_dir}' is a file; give the run's folder")
    if not (run_dir / "config.json").is_file():
        raise RunFolderError(f"--resume '{run_dir}' is not a mope run folder (no config.json)")
    cfg = Config.load(run_dir / "config.json")
    from mope.experiments.runs import run_status, train_run  # torch only once the folder is checked

    if device is not None:
        cfg = cfg.replace(device=device)
    if overwrite:
        result = train_run(cfg, run_dir, progress=progress, overwrite=True)
        _print_final(cfg, result)
        return
    if run_status(run_dir) == "new":
        typer.echo(f"{run_dir} has no checkpoint yet (it was stopped before step {cfg.run.checkpoint_every}): "
                   "starting it over with its saved config", err=True)
    result = train_run(cfg, run_dir, progress=progress, resume=True)
    _print_final(cfg, result)


def _print_final(cfg: Config, result: Any) -> None:
    import math

    f = {k: result.final.get(k, float("nan")) for k in ("cr", "hv", "eum", "eum_optimal", "optimal_share",
                                                          "timeout_share", "path_error")}
    truth = f"  path error {f['path_error']:.3f}" if math.isfinite(f["path_error"]) else ""
    typer.echo(
        f"{cfg.algo} on {cfg.env_id}, {cfg.total_steps} steps, seed {cfg.seed}: CR {f['cr']:.3f}  HV {f['hv']:.2f}  "
        f"EUM {f['eum']:.3f} (optimum {f['eum_optimal']:.3f})  optimal share {f['optimal_share']:.3f}  "
        f"timeouts {f['timeout_share']:.3f}{truth}  [{result.wall_s:.0f} s]\nrun folder: {result.out_dir}"
    )


def _print_metrics(res: dict[str, float]) -> None:
    for key in ("cr", "precision", "recall", "hv", "eum", "eum_optimal", "eum_gap", "optimal_share",
                "cardinality", "timeout_share", "path_error", "state_error", "overestimation", "win_share",
                "loss_share", "out_share"):
        if key in res and res[key] == res[key]:  # NaN: not measured on this environment
            typer.echo(f"{key:>14}: {res[key]:.4f}")


@app.command("eval")
@handles_errors()
def eval_(
    run_or_checkpoint: Annotated[Path, typer.Argument(help="A run folder or a checkpoint file.")],
    prefs: Annotated[int, typer.Option(help="Number of uniform preferences.")] = 2000,
    seed: Annotated[int | None, typer.Option(help="Seed of the preference set (default: the run's).")] = None,
    out: Annotated[Path | None, typer.Option(help="Solutions CSV (default next to the checkpoint).")] = None,
    device: Annotated[str | None, typer.Option(help="cpu, cuda or auto (default: the run's).")] = None,
) -> None:
    """Evaluate a trained agent: CR, HV, EUM and more; writes the solution set as CSV."""
    from mope.evaluation.evaluator import MAX_EVAL_PREFS
    from mope.experiments.runs import evaluate_checkpoint, resolve_checkpoint

    ckpt = resolve_checkpoint(run_or_checkpoint)
    target = out or ckpt.parent / f"{ckpt.stem}_solutions_{prefs}.csv"
    if 20_000 <= prefs <= MAX_EVAL_PREFS:
        typer.echo(f"note: evaluating {prefs} preferences (the paper uses 2000) takes a while", err=True)
    res, _ = evaluate_checkpoint(ckpt, prefs, seed, target, device)
    typer.echo(f"checkpoint: {ckpt}")
    _print_metrics(res)
    typer.echo(f"solutions: {target}")


@app.command()
@handles_errors()
def act(
    checkpoint: Annotated[Path, typer.Argument(help="A run folder or a checkpoint file.")],
    pref: Annotated[str, typer.Option(help="Preference, e.g. 0.3,0.7.")],
    video: Annotated[Path | None, typer.Option(help="Also record the episode as a GIF (rgb_array envs).")] = None,
    seed: Annotated[int, typer.Option(help="Seed of the episode's reset.")] = 0,
    device: Annotated[str | None, typer.Option(help="cpu, cuda or auto (default: the run's).")] = None,
) -> None:
    """Play one greedy episode under a preference and print its return vector (optionally record a GIF)."""
    quiet_media()
    from mope.evaluation.video import check_video_path, record_video

    _check_pref_of_run(checkpoint, pref)  # bad input is refused before torch is imported
    if video is not None:
        check_video_path(video)
    from mope.experiments.runs import load_agent, play

    agent = load_agent(checkpoint, device)
    sols = play(agent, pref, seed=seed)
    if video is not None:
        rec = record_video(agent, agent.config.env_id, sols.prefs[0], video, seed=seed,
                           max_steps=agent.config.max_episode_steps)
        outcome = f", outcome: {rec['outcome']}" if rec.get("outcome") else ""
        typer.echo(f"video: {rec['path']} ({rec['frames']} frames{outcome})")
    fmt = ", ".join
    typer.echo(f"preference: [{fmt(f'{x:.4g}' for x in sols.prefs[0])}]")
    typer.echo(f"return: [{fmt(f'{x:.4g}' for x in sols.returns[0])}]")
    typer.echo(f"discounted return: [{fmt(f'{x:.4g}' for x in sols.discounted[0])}]")
    typer.echo(f"length: {int(sols.lengths[0])}{'' if sols.terminated[0] else ' (time limit)'}")


@app.command()
@handles_errors()
def diagnose(
    run_or_checkpoint: Annotated[Path, typer.Argument(help="A run folder or a checkpoint file.")],
    prefs: Annotated[int, typer.Option(help="Equally spaced preferences.")] = 101,
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
    device: Annotated[str | None, typer.Option(help="cpu, cuda or auto (default: the run's).")] = None,
) -> None:
    """Measure a trained agent against the exact Q* (environments with known dynamics: Deep-Sea-Treasure and
    resource-gathering)."""
    from mope.evaluation.diagnose import diagnose as run_diagnosis
    from mope.experiments.runs import load_agent, resolve_checkpoint

    if prefs < 1:
        raise ConfigError(f"--prefs {prefs} is out of range: must be >= 1")
    ckpt = resolve_checkpoint(run_or_checkpoint)
    agent = load_agent(ckpt, device)
    res = run_diagnosis(agent, agent.env, agent.config.gamma, prefs)
    if as_json:
        typer.echo(json.dumps({"checkpoint": str(ckpt), **res}, indent=2))
        return
    typer.echo(f"checkpoint: {ckpt} (step {agent.global_step})")
    for key, value in res.items():
        typer.echo(f"{key:>20}: {value:.4f}")


reproduce_app = typer.Typer(no_args_is_help=True, help="Reproduce the paper's experiments.")
app.add_typer(reproduce_app, name="reproduce")


@reproduce_app.command("dst")
@handles_errors(interrupted=RESUME_HINT)
def reproduce_dst_cmd(
    out: Annotated[Path, typer.Option(help="Output folder (runs, figures, table).")] = Path("runs/reproduce-dst"),
    seeds: Annotated[str, typer.Option(help="Seeds per variant: N (0..N-1; the paper-scale run: 10), a range 5-9 "
                                            "or a list 0,5,7.")] = "3",
    steps: Annotated[int, typer.Option(help="Environment steps per run.")] = 20_000,
    eval_every: Annotated[int, typer.Option(help="Evaluate CR every N steps.")] = 1000,
    algos: Annotated[str, typer.Option(help="Comma-separated variants.")] = "eql,ee,pe,mope",
    env: Annotated[str, typer.Option(help="A Deep-Sea-Treasure map: deep-sea-treasure-v0 (MO-Gymnasium's), "
                                          "mope/deep-sea-treasure-seabed-v0 (the EQL authors' seabed rule), ...")
                   ] = "deep-sea-treasure-v0",
    workers: Annotated[int, typer.Option(help="Parallel training processes.")] = 2,
    set_: Annotated[list[str] | None, typer.Option("--set", help="Config override for every run: KEY=VALUE.")] = None,
    device: Annotated[str | None, typer.Option(help="cpu, cuda or auto.")] = None,
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
) -> None:
    """Fig. 2 and Fig. 3 of the paper on Deep-Sea-Treasure: four variants x seeds, figures and a table."""
    from mope.paper.dst import reproduce_dst

    res = reproduce_dst(out, seeds=seeds, steps=steps, eval_every=eval_every,
                        algos=tuple(a.strip() for a in algos.split(",") if a.strip()), workers=workers, env_id=env,
                        progress=progress, **{**parse_overrides(set_), **({"device": device} if device else {})})
    typer.echo(res["table"])
    typer.echo(f"figures and table in {res['out']} (this invocation trained for {res['train_wall_s']:.0f} s; "
               f"the runs' own wall times sum to {res['runs_wall_s']:.0f} s)")


@reproduce_app.command("confrontation")
@handles_errors(interrupted=RESUME_HINT)
def reproduce_confrontation_cmd(
    out: Annotated[Path, typer.Option(help="Output folder (runs, figures, table).")] = Path(
        "runs/reproduce-confrontation"),
    seeds: Annotated[str, typer.Option(help="Seeds per method: N (0..N-1), a range 5-9 or a list 0,5,7.")] = "1",
    steps: Annotated[int, typer.Option(help="Environment steps per agent (and per PPO policy, see --ppo-budget).")
                     ] = 15_000,
    ppo_prefs: Annotated[int, typer.Option(help="K preferences, one PPO policy each.")] = 11,
    eval_prefs: Annotated[int, typer.Option(help="Uniform preferences for EQL and MoPE.")] = 100,
    episodes: Annotated[int, typer.Option(help="Evaluation episodes per preference: the common start states.")] = 100,
    ppo_budget: Annotated[str, typer.Option(help="each: every PPO policy gets --steps; shared: they split it.")
                          ] = "each",
    workers: Annotated[int, typer.Option(help="Parallel training processes.")] = 2,
    set_: Annotated[list[str] | None, typer.Option("--set", help="Config override for the agents: KEY=VALUE.")] = None,
    device: Annotated[str, typer.Option(help="cpu, cuda or auto.")] = "cpu",
    progress: Annotated[bool, typer.Option(help="Show a progress bar.")] = True,
) -> None:
    """Fig. 5 and Fig. 6 of the paper on the robot game: PPO x K, EQL, MoPE alone and MoPE with demonstrations."""
    from mope.paper.confrontation import reproduce_confrontation

    res = reproduce_confrontation(out, seeds=seeds, steps=steps, ppo_prefs=ppo_prefs, eval_prefs=eval_prefs,
                                  episodes=episodes, workers=workers, progress=progress, ppo_budget=ppo_budget,
                                  device=device, **parse_overrides(set_))
    typer.echo(res["table"])
    typer.echo(f"figures and table in {res['out']} (training {res['train_wall_s']:.0f} s, "
               f"evaluation {res['eval_wall_s']:.0f} s)")


@app.command()
@handles_errors(interrupted="running trials saved their state: run the same command again to resume")
def sweep(
    spec: Annotated[Path, typer.Argument(help="YAML sweep spec (see examples/sweep-dst.yaml).")],
    backend: Annotated[str, typer.Option(help="local (processes) or ray.")] = "local",
    address: Annotated[str | None, typer.Option(help="Ray address: auto, ray://host:10001.")] = None,
    workers: Annotated[int | None, typer.Option(help="Trials at once (default: all cores).")] = None,
    out: Annotated[Path | None, typer.Option(help="Sweep folder (default runs/<name>).")] = None,
    set_: Annotated[list[str] | None, typer.Option("--set", help="Override/pin: --set total_steps=5000.")] = None,
    seeds: Annotated[str | None, typer.Option(help="Seeds to run: N (0..N-1), a range 5-9, or a list 0,5,7.")
                     ] = None,
    progress: Annotated[bool, typer.Option(help="Show the live summary.")] = True,
) -> None:
    """Run a grid of trainings; re-running skips finished trials and resumes interrupted ones."""
    from mope.experiments.sweep import sweep_command

    results = sweep_command(spec, out, backend, address, workers, set_, seeds, progress)
    if any(r.status == "failed" for r in results):
        raise typer.Exit(1)


@app.command()
@handles_errors(interrupted=RESUME_HINT)
def benchmark(
    out: Annotated[Path, typer.Option(help="Folder of the runs (and of the report, unless --report-dir).")] = Path(
        "runs/benchmark"),
    envs: Annotated[str | None, typer.Option(help="Comma-separated environments [default: all of the benchmark's]")
                    ] = None,
    methods: Annotated[str | None, typer.Option(
        help="Comma-separated: mope, eql, mope-paper, eql-paper, envelope, or an older default (mope-eps-greedy, "
             "mope-eps-greedy-unbounded, ...: mope.paper.benchmark.METHODS) "
             "\\[default: mope,eql,mope-paper, and envelope when morl-baselines is installed]")] = None,
    seeds: Annotated[str, typer.Option(help="Seeds per environment and method: N (0..N-1), a range 5-9 or a list "
                                            "0,5,7.")] = "5",
    quick: Annotated[bool, typer.Option(help="One seed, small budgets: a first look (CI runs it).")] = False,
    steps: Annotated[int | None, typer.Option(help="Budget of every environment [default: each one's own]")] = None,
    workers: Annotated[int | None, typer.Option(help="Jobs at once [default: all cores]")] = None,
    backend: Annotated[str, typer.Option(help="local (processes) or ray.")] = "local",
    address: Annotated[str | None, typer.Option(help="Ray address: auto, ray://host:10001.")] = None,
    report_dir: Annotated[Path | None, typer.Option(help="Where the table and figures go [default: --out]")] = None,
    progress: Annotated[bool, typer.Option(help="Show the live line.")] = True,
    report_only: Annotated[bool, typer.Option(
        help="Train nothing: rebuild the table and figures from the finished runs already in --out.")] = False,
) -> None:
    """mope's variants beside morl-baselines' Envelope on several environments: one table and figure per env.

    The report covers every finished run in --out, so a benchmark can be run in pieces (one environment or some
    seeds per call, even on different machines) into one folder.
    """
    from mope.paper.benchmark import run_benchmark

    def split(text: str | None) -> list[str] | None:
        return [x.strip() for x in text.split(",") if x.strip()] if text else None

    res = run_benchmark(out, split(envs), split(methods), seeds, quick, steps, workers, backend, address,
                        report_dir, progress, command="mope " + " ".join(sys.argv[1:]), report_only=report_only)
    typer.echo(res["table"])
    typer.echo(f"table and figures in {res['out']} ({res['wall_s']:.0f} s)")


@app.command()
@handles_errors()
def report(
    runs_dir: Annotated[Path, typer.Argument(help="Sweep folder or any folder of runs.")],
    out: Annotated[Path | None, typer.Option(help="Output folder (default RUNS_DIR/report).")] = None,
    split_mismatched: Annotated[bool, typer.Option(
        help="Group runs that differ beyond the swept fields separately.")] = False,
) -> None:
    """Aggregate runs across seeds: table (mean, std, bootstrap 95% CI, IQM), curves and fronts."""
    from mope.experiments.report import report_command

    report_command(runs_dir, out, split_mismatched)


@app.command()
def envs() -> None:
    """List MO-Gymnasium environments mope's agents can use directly (discrete actions)."""
    import warnings

    quiet_media()  # probed pygame envs: no sound card warnings
    import gymnasium as gym

    from mope.envs import make_env

    for env_id in sorted(gym.registry):
        spec = gym.registry[env_id]
        if "mo_gymnasium" not in str(spec.entry_point) and "mope" not in str(spec.entry_point):
            continue
        try:
            with warnings.catch_warnings():  # deprecation notices of envs we only probe
                warnings.simplefilter("ignore")
                make_env(env_id).close()
        except Exception:  # noqa: BLE001 - skip what does not fit or needs extra packages
            continue
        typer.echo(env_id)


def expand_set_args(argv: list[str]) -> list[str]:
    """Let one ``--set`` take several ``KEY=VALUE`` pairs: ``--set a=1 b=2`` becomes ``--set a=1 --set b=2``.

    After a ``--set`` and its first pair, every following argument that holds ``=`` and does not start with
    ``-`` is another pair.
    """
    out: list[str] = []
    state = ""  # "": outside, "value": the next argument is --set's own value, "more": extra pairs may follow
    for arg in argv:
        if state == "value":
            out.append(arg)
            state = "more"
        elif state == "more" and not arg.startswith("-") and "=" in arg:
            out += ["--set", arg]
        else:
            out.append(arg)
            state = "value" if arg == "--set" else "more" if arg.startswith("--set=") else ""
    return out


def main() -> None:
    """Entry point of the ``mope`` script: usage errors and library errors are one ``error:`` line, exit 2."""
    from typer._click.exceptions import NoArgsIsHelpError, UsageError

    with warnings.catch_warnings(record=True) as caught:
        try:
            rv = app(args=expand_set_args(sys.argv[1:]), standalone_mode=False)
        except UsageError as exc:
            if not isinstance(exc, NoArgsIsHelpError):
                typer.echo(f"error: {one_line(exc.format_message())}", err=True)
            sys.exit(2)
        except typer.Abort:
            sys.exit(130)
        except MopeError as exc:  # anything that escaped a command
            typer.echo(f"error: {exc}", err=True)
            sys.exit(2)
        except OSError as exc:  # a file system failure no command expected (a full disk, a vanished folder)
            what = "the disk is full" if is_disk_full(exc) else exc.strerror or str(exc)
            where = f" ('{exc.filename}')" if exc.filename else ""
            typer.echo(f"error: {one_line(f'{what}{where}')}", err=True)
            sys.exit(2)
    code = rv if isinstance(rv, int) else 0
    if code != 2:  # warnings would only stand before the error line; shown once each when the command succeeds
        for w in {(str(w.message), w.category): w for w in caught}.values():
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    sys.exit(code)


if __name__ == "__main__":
    main()
