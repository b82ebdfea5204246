"""The one configuration object shared by the CLI, the Python API and saved runs.

``Config`` holds every hyperparameter of the paper and of the training loop. ``mope train`` builds one from
its flags, ``MoPE(env, **overrides)`` builds one from keyword arguments, and every run folder and
checkpoint stores ``Config.to_dict()``; :meth:`Config.from_dict` reads it back. Values are validated when
the object is built, with one-line errors that name the bad value.

The defaults are the learning study's recipe (docs/design.md, "The learner"; docs/results/learning-study); the
``paper`` preset holds the paper's settings, and where the paper is silent, what Yang et al. (2019) or
morl-baselines use on Deep-Sea-Treasure.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import re
import types
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mope.errors import ConfigError, short_repr, suggest

#: Algorithm name -> (experience_exploration, preference_exploration). Fig. 2 of the paper. The one place that
#: maps a variant to its switches (read it through :meth:`Config.for_algo`).
ALGOS: dict[str, tuple[bool, bool]] = {
    "eql": (False, False),
    "ee": (True, False),
    "pe": (False, True),
    "mope": (True, True),
}

ENVELOPE_PREFS = ("relabel", "batch", "both", "own")
ENCODINGS = ("scale", "onehot", "joint", "auto")
Q_HEADS = ("conditioned", "convex")
#: Forms of the scalarised loss L^B (Config.lb_loss).
LB_LOSSES = ("squared", "abs")
DEVICES = ("cpu", "cuda", "auto")


#: The target network's Polyak weight held constant for the whole run: mope's default before the late anneal
#: (issue 33). The presets and the robot game keep it; ``mope benchmark``'s ``*-const`` methods pin it.
CONSTANT_TARGET: dict[str, Any] = {"target_tau_end": None, "target_tau_anneal_from": 0.0}

#: Epsilon's decay and the replay capacity before they followed the run's length (issue 33, later on 2026-12-06): a
#: fixed 10k and 20k, whatever the budget. The presets, the robot game and ``mope benchmark``'s ``*-eps10k`` methods
#: keep them.
SHORT_EXPLORATION: dict[str, Any] = {"epsilon_decay_steps": 10_000, "buffer_size": 20_000}

#: One-step epsilon-greedy and targets clamped by the reward space only: mope's defaults before ez-greedy and the
#: seen-return bound (issue 33, 2026-12-07). The presets, the robot game and ``mope benchmark``'s older methods keep
#: them.
PLAIN_EPSILON: dict[str, Any] = {"epsilon_repeat_mu": None}
UNBOUNDED: dict[str, Any] = {"seen_bound_margin": None}

#: Named sets of defaults: ``Config.from_dict({"preset": name, ...})``, ``mope train --preset name``.
#: ``mope`` is the dataclass defaults (see docs/design.md, "The learner"); ``paper`` is the paper's literal settings
#: as mope 0.1 ran them (the defaults before the learning study, double Q-learning and target clipping included);
#: ``envelope`` is morl-baselines' Envelope example (examples/envelope_minecart.py) with gamma 0.99 and epsilon
#: decayed over 10k steps, for the EQL variant.
PRESETS: dict[str, dict[str, Any]] = {
    "mope": {},
    "paper": {"q_head": "conditioned", "obs_encoding": "scale", "hidden_sizes": [64, 128, 128, 64],
              "learning_rate": 1e-3, "learning_rate_end": None, "batch_size": 32, "target_tau": None,
              "target_update_freq": 100, "max_grad_norm": 10.0, "n_omega": 64, "relabel_broad": 0.0,
              "envelope_prefs": "relabel", "return_mix": 0.0, "n_step": 1, "epsilon_decay_steps": 10_000,
              "buffer_size": 20_000, "reward_norm": None, "lb_loss": "abs", "lb_weight": 1.0, **CONSTANT_TARGET,
              **PLAIN_EPSILON, **UNBOUNDED},
    "envelope": {"q_head": "conditioned", "obs_encoding": "scale", "hidden_sizes": [256, 256, 256, 256],
                 "learning_rate": 3e-4, "learning_rate_end": None, "batch_size": 64, "n_omega": 4,
                 "target_tau": None, "target_update_freq": 1000, "max_grad_norm": 0.1, "lb_homotopy_steps": 10_000,
                 "relabel_broad": 0.0, "envelope_prefs": "relabel", "clip_targets": False, "learning_starts": 100,
                 "per_alpha": 0.6, "return_mix": 0.0, "n_step": 1, "epsilon_decay_steps": 10_000,
                 "buffer_size": 20_000, "reward_norm": None, "lb_weight": 1.0, **CONSTANT_TARGET,
                 **PLAIN_EPSILON, **UNBOUNDED},
}

#: Per-environment defaults: ``mope train --env ID`` and ``MoPE(ID)`` use them for every setting not given (by a
#: flag, ``--set``, a config file or a keyword); a preset other than ``mope`` (``--preset paper``) skips them. Each
#: is the recipe its environment's study chose (docs/results/game-study for the robot game: 4 envs, one update per
#: 4 env steps, beat 8 envs on both seeds of an 80k-step probe, at about 1.8x the wall time; 5,000 DQfD
#: pre-training updates on the demonstrations beat none on wins, exits and EU over 10 seeds of 200k steps). The game
#: keeps the constant target: on 5 paired seeds the late anneal won 0.031 less at w_catch 0.8-1, past the 0.03 its
#: rule allowed (docs/results/game-study/late-target-amd). It keeps one-step epsilon-greedy and the reward space's
#: clamp too, and the absolute L^B of weight 1: ez-greedy, the seen-return bound and the squared L^B were not
#: measured on it.
ENV_DEFAULTS: dict[str, dict[str, Any]] = {
    "mope/RobotConfrontationDiscrete-v0": {"n_envs": 4, "buffer_size": 100_000, "epsilon_decay_steps": 10_000,
                                           "demos": "scripted",
                                           "demo_episodes": 50, "demo_batch_share": 0.25,
                                           "demo_pretrain_steps": 5_000,
                                           "eval_every": 20_000, "eval_prefs": 200, "lb_loss": "abs",
                                           "lb_weight": 1.0, **CONSTANT_TARGET, **PLAIN_EPSILON, **UNBOUNDED},
}

#: Fields added after mope 0.2.0, with the values that reproduce the runs saved before them: a saved config (it has
#: every other field) that lacks them is read with these values, not with today's defaults.
LATER_FIELDS: dict[str, Any] = {"n_critics": 1, "component_anchor_weight": 0.0, "reward_scale": 1.0,
                                "return_mix": 0.0, "return_window": 2_000, "n_step": 1, "n_envs": 1,
                                "train_freq": 1, "demos": "", "demo_episodes": 100, "demo_margin": 0.8,
                                "demo_loss_weight": 1.0, "demo_pretrain_steps": 0,
                                "demo_batch_share": 0.0, "demo_roll_in": 0, "demo_label_weight": 0.0,
                                "seen_bound_margin": None, "return_timeout_bootstrap": True,
                                "reward_norm": None, "layer_norm": False, "consistent_bellman": False,
                                "target_tau_end": None, "target_tau_anneal_from": 0.0, "epsilon_repeat_mu": None,
                                "lb_loss": "abs"}


def check_preset(name: str) -> str:
    """Return ``name`` if it names a preset, else raise a :class:`ConfigError` with the closest name."""
    if name not in PRESETS:
        raise ConfigError(f"unknown preset '{name}'{suggest(name, PRESETS)}; choose one of {', '.join(PRESETS)}")
    return name


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_num(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _finite(x: Any) -> bool:
    return _is_num(x) and math.isfinite(x)


#: Plain type -> (check, what a value of it must be). :func:`_type_check` builds the check of a field from its real
#: type hint (``typing.get_type_hints``): these types, ``X | None`` and ``tuple[X, ...]`` of them.
_SCALAR_CHECKS: dict[type, tuple[Callable[[Any], bool], str]] = {
    int: (_is_int, "an integer"),
    float: (_is_num, "a number"),
    bool: (lambda x: isinstance(x, bool), "true or false"),
    str: (lambda x: isinstance(x, str), "a string"),
}
_PLURALS = {"an integer": "integers", "a number": "numbers", "true or false": "booleans", "a string": "strings"}


def _type_check(hint: Any) -> tuple[Callable[[Any], bool], str] | None:
    """(check, what the value must be) for a type hint; None for a nested settings dataclass (checked by itself).

    Raises:
        TypeError: for a hint no check is written for (a new field of another type must add one here).
    """
    args = typing.get_args(hint)
    if isinstance(hint, types.UnionType) and len(args) == 2 and type(None) in args:
        inner = _type_check(next(a for a in args if a is not type(None)))
        if inner is not None:
            ok, what = inner
            return (lambda x: x is None or ok(x)), f"{what} or null"
    elif typing.get_origin(hint) is tuple and len(args) == 2 and args[1] is Ellipsis and args[0] in _SCALAR_CHECKS:
        item, what = _SCALAR_CHECKS[args[0]]
        return (lambda x: isinstance(x, (list, tuple)) and all(item(v) for v in x)), f"a list of {_PLURALS[what]}"
    elif hint in _SCALAR_CHECKS:
        return _SCALAR_CHECKS[hint]
    elif dataclasses.is_dataclass(hint):
        return None
    raise TypeError(f"no type check for the type hint {hint!r}")


@functools.cache
def _field_checks(cls: type) -> dict[str, tuple[Callable[[Any], bool], str]]:
    """The type check of every field of a settings dataclass, from its real type hints."""
    hints = typing.get_type_hints(cls)
    checks = {f.name: _type_check(hints[f.name]) for f in dataclasses.fields(cls)}
    return {name: check for name, check in checks.items() if check is not None}


#: Integers must fit a signed 64-bit integer: numpy's and torch's seeds, array sizes and step counters are 64-bit,
#: and a bigger number fails deep inside them (``Overflow when unpacking long long``).
INT64_MAX = 2**63 - 1


def _too_big(value: Any) -> bool:
    """An integer (or an integer in a list) beyond 64 bits."""
    if isinstance(value, (list, tuple)):
        return any(_is_int(v) and abs(v) > INT64_MAX for v in value)
    return _is_int(value) and abs(value) > INT64_MAX


def _check_types(obj: Any) -> None:
    """Raise :class:`ConfigError` for a field of the wrong type (a quoted number, a bool for a count, ...) or an
    integer beyond 64 bits. Values are shown cut short: no check formats a huge value whole."""
    for name, (ok, what) in _field_checks(type(obj)).items():
        value = getattr(obj, name)
        if not ok(value):
            raise ConfigError(f"{name}={short_repr(value)} is not {what}")
        if _too_big(value):
            raise ConfigError(f"{name}={short_repr(value)} is out of range: integers must lie in "
                              f"[-{INT64_MAX}, {INT64_MAX}] (64 bits)")


def _need(obj: Any, ok: bool, name: str, allowed: str) -> None:
    if not ok:
        raise ConfigError(f"{name}={short_repr(getattr(obj, name))} is out of range: {allowed}")


@dataclass
class RunSettings:
    """How a run is executed and recorded: device, evaluation, checkpoints, logs. Nothing here changes learning.

    The agent reads only ``device`` (where its networks live); the runner (:mod:`mope.agent.runner`,
    :func:`mope.experiments.runs.train_run`) reads the rest.
    """

    device: str = "cpu"
    #: torch intra-op threads; 0 leaves torch's default. 1 is fastest for these small networks on 2 cores.
    torch_threads: int = 1
    eval_every: int = 1_000
    eval_prefs: int = 2_000
    #: Reference point for hypervolume; ``None`` uses the environment's documented default.
    ref_point: tuple[float, ...] | None = None
    checkpoint_every: int = 5_000
    #: Training statistics (losses, |TD|, Q, MI bonus) are averaged over this many steps and logged.
    log_every: int = 100

    def __post_init__(self) -> None:
        _check_types(self)
        if self.ref_point is not None:
            self.ref_point = tuple(float(x) for x in self.ref_point)
        need = functools.partial(_need, self)
        need(self.device in DEVICES, "device", f"choose one of {', '.join(DEVICES)}")
        need(self.torch_threads >= 0, "torch_threads", "must be >= 0")
        need(self.eval_every >= 0, "eval_every", "must be >= 0 (0: never)")
        need(self.eval_prefs >= 1, "eval_prefs", "must be >= 1")
        need(self.ref_point is None or all(math.isfinite(x) for x in self.ref_point), "ref_point",
             "must be finite numbers")
        need(self.checkpoint_every >= 0, "checkpoint_every", "must be >= 0 (0: only at the end)")
        need(self.log_every >= 1, "log_every", "must be >= 1")

    @classmethod
    def field_names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]


@dataclass(init=False)
class Config:
    """All settings of one training run: the learner's hyperparameters, and ``run`` (:class:`RunSettings`).

    Grouped as task, EQL core, prioritized replay, EE, PE, demonstrations, and the options the studies did not
    adopt; ``algo`` follows from the two exploration switches. Every setting, ``run``'s included, is one flat key
    for ``Config(**kwargs)``, ``--set KEY=VALUE``, sweep specs and ``config.json`` (in code: ``config.run.X``).
    """

    # --- task ------------------------------------------------------------------------------------------
    env_id: str = "deep-sea-treasure-v0"
    seed: int = 0
    total_steps: int = 20_000
    max_episode_steps: int | None = None  # episode time limit; None: the environment's (100 on Deep-Sea-Treasure)
    #: How observations enter the networks: "scale" (a bounded Box to [0, 1]), "onehot" (each coordinate of an
    #: integer Box one-hot), "joint" (a small integer Box's whole cell one-hot), "auto" (onehot if small, else scale).
    obs_encoding: str = "auto"

    # --- EQL core (paper eq. 4; Yang et al. 2019) ------------------------------------------------------------
    gamma: float = 0.99
    #: Largest per-step reward the learner sees: where the reward space allows more, all rewards are scaled down to
    #: it alike (no greedy action changes; mope.agent.agent.learner_reward_scale). None: off.
    reward_norm: float | None = 25.0
    #: Q-network head: "conditioned" (the paper: omega is an input, one vector per action and objective) or
    #: "convex" (C return vectors per action; Q(s, a, w) is the one w prefers: mope.agent.networks.ConvexQNetwork).
    q_head: str = "convex"
    n_components: int = 12  # C, return vectors per action of the convex head
    component_loss_weight: float = 1.0  # of the convex head's component loss (targets train their nearest component)
    hidden_sizes: tuple[int, ...] = (256, 256, 256)
    layer_norm: bool = False  # LayerNorm before every hidden ReLU of the Q-network (mope.agent.networks.mlp)
    learning_rate: float = 3e-4
    learning_rate_end: float | None = 3e-5  # cosine decay of the learning rate to it over total_steps (None: constant)
    batch_size: int = 128
    buffer_size: int | None = None  # None: the whole run, at least 20k and at most 1M (buffer_capacity)
    learning_starts: int = 200
    n_envs: int = 1  # training envs stepped together, one forward pass acting for all (SB3's ``n_envs``)
    #: Collection steps (each ``n_envs`` env steps) per update round (SB3's ``train_freq``) ...
    train_freq: int = 1
    #: ... and gradient updates per round (SB3's ``gradient_steps``), each followed by the Polyak step.
    gradient_steps: int = 1
    target_update_freq: int = 100  # hard target-network copy every this many env steps (Yang et al. use 100)
    #: Polyak weight of the target network (None: the hard copy above), on a cosine to target_tau_end (None: constant)
    #: from the fraction target_tau_anneal_from of the run: late updates no longer move the policy (results/target-tau).
    target_tau: float | None = 0.005
    target_tau_end: float | None = 1e-4
    target_tau_anneal_from: float = 0.5
    #: Weight of the episode's greedy-tail return (losses.greedy_tail_returns, docs/results/return-mix) in its own
    #: preference's target row (0: off), from returns at most return_window steps old; a tail the time limit cut ends on
    #: V(s_T), or there with return_timeout_bootstrap=False.
    return_mix: float = 0.5
    return_window: int = 2_000
    return_timeout_bootstrap: bool = True
    n_step: int = 1  # stored rewards per target row, cut at its first non-greedy action (watkins_n_step_targets)
    #: L = L^A + lb_weight * L^B (weight 1 in the paper): "squared" (w^T y - w^T Q)^2 as Yang et al.'s code (the mean),
    #: or "abs" as eq. 4 is written (the median: a random risk as none). Weight 4: DST's precision (results/lb-loss)
    lb_weight: float = 4.0
    lb_loss: str = "squared"
    #: Homotopy of Yang et al.: the weight of L^B rises linearly from 0 to lb_weight over this many steps (0: off).
    lb_homotopy_steps: int = 0
    max_grad_norm: float | None = 1.0
    #: Double Q: (a*, w'*) of the envelope target picked by the online network, valued by the target (docs/design.md).
    double_q: bool = True
    #: Clamp the targets y to the returns the reward bounds allow (not in the paper; see docs/design.md), and with
    #: kappa >= 0 the upper clamp to at most the largest return seen plus kappa x the range seen (None: not).
    clip_targets: bool = True
    seen_bound_margin: float | None = 0.1
    epsilon_start: float = 1.0
    epsilon_end: float = 0.05
    epsilon_decay_steps: int | None = None  # None: half the run, at least 10k (epsilon_decay_steps_of)
    #: ez-greedy (Dabney et al. 2021): keep a random action n ~ zeta(mu) steps, or to a wall; None: one step.
    epsilon_repeat_mu: float | None = 2.0
    #: Preferences per transition (N_omega): EQL's uniform, shared by the batch (Yang's ``weight_num``); EE's near it.
    n_omega: int = 32

    # --- prioritized replay (Schaul et al. 2016) ------------------------------------------------------------
    per: bool = True
    per_alpha: float = 0.6
    per_beta_start: float = 0.4
    per_eps: float = 0.01

    # --- experience exploration (EE): relabeling, eq. 5-7 ----------------------------------------------------
    experience_exploration: bool = True
    sigma_omega: float = 0.04
    #: Share of a transition's N_omega relabeled preferences drawn uniformly from the whole simplex instead of
    #: within sigma_omega (EE only; 0 is the paper's similar-preference relabeling).
    relabel_broad: float = 0.5
    #: The envelope max's preferences: the transition's relabeled set ("relabel"), the batch's acting ones ("batch"),
    #: or both; "own" is no envelope (each row at its own preference, as morl-baselines' ``envelope=False``).
    envelope_prefs: str = "own"
    mi_alpha: float = 0.1  # weight alpha of the mutual-information term in the priority (eq. 7)
    disc_hidden: tuple[int, ...] = (64, 64)
    disc_learning_rate: float = 1e-3

    # --- preference exploration (PE) ---------------------------------------------------------------------------
    preference_exploration: bool = True
    n_intervals: int = 10
    pe_count_offset: float = 0.01  # the constant c in p(omega) ~ (N_i + c)^(-1/2); the paper uses 0.01

    # --- demonstrations (DQfD, Hester et al. 2018; mope.agent.demonstrations) ---------------------------------
    #: "" (none), "scripted" (the env's scripted policies, each at the preferences it is good at), or an .npz file
    #: of episodes (mope.agent.demonstrations.save_demonstrations). Kept in replay for good.
    demos: str = ""
    #: Episodes collected from each scripted policy (a file is used whole).
    demo_episodes: int = 100
    #: The large margin l(a_E, a) of J_E, and J_E's weight in the loss (0: replayed, without the margin loss).
    demo_margin: float = 0.8
    demo_loss_weight: float = 1.0
    #: Updates on the demonstrations alone before the first env step.
    demo_pretrain_steps: int = 0
    #: Share of every batch drawn uniformly from the demonstrations (0: they compete in prioritized replay).
    demo_batch_share: float = 0.0
    #: Scripted demonstrations start after U{0..demo_roll_in} unrecorded random actions; 0: none (game-study).
    demo_roll_in: int = 0
    #: Weight of J_E on the learner's own states, labelled by the scripted policies (DAgger); 0: off (game-study).
    demo_label_weight: float = 0.0

    # --- experimental: tried against the mirrored map's divergence, not adopted (off; docs/design.md) ---------
    #: H, heads of the convex head whose minimum is Q (Maxmin, Lan et al. 2020); 1: one head (always, conditioned).
    n_critics: int = 1
    #: Within the component loss, weight of the pull of every component toward its nearest target (0: off).
    component_anchor_weight: float = 0.0
    #: Rewards times this constant in the targets (all objectives alike: no greedy action changes); 1: off.
    reward_scale: float = 1.0
    #: Bellemare et al.'s consistent operator where s' = s (targets.consistent_values; convex head, one step only).
    consistent_bellman: bool = False

    run: RunSettings = field(default_factory=RunSettings)

    def __init__(self, **settings: Any) -> None:
        """Every setting by keyword, run settings flat (``Config(eval_prefs=100)``) or as ``run``; an unknown key is
        a :class:`ConfigError` that names the closest field, not a TypeError."""
        run = settings.pop("run", None)
        run_settings = {key: settings.pop(key) for key in list(settings) if key in _RUN_NAMES}
        for key in settings:
            if key not in _HYPERPARAMETER_NAMES:
                raise unknown_key_error(key)
        for f in dataclasses.fields(self):
            if f.name != "run":
                default = f.default_factory() if f.default is dataclasses.MISSING else f.default  # type: ignore[misc]
                setattr(self, f.name, settings.get(f.name, default))
        if run_settings:
            run = RunSettings(**{**(dataclasses.asdict(run) if isinstance(run, RunSettings) else {}), **run_settings})
        self.run = RunSettings() if run is None else run
        self.__post_init__()

    def __post_init__(self) -> None:
        _check_types(self)
        if not isinstance(self.run, RunSettings):
            raise ConfigError(f"run={self.run!r} is not a RunSettings")
        self.hidden_sizes = tuple(self.hidden_sizes)
        self.disc_hidden = tuple(self.disc_hidden)
        self.validate()

    @property
    def algo(self) -> str:
        """Name of the variant: ``eql``, ``ee``, ``pe`` or ``mope``."""
        flags = (self.experience_exploration, self.preference_exploration)
        return next(name for name, f in ALGOS.items() if f == flags)

    @classmethod
    def for_algo(cls, algo: str, **overrides: Any) -> Config:
        """Build the config of a named variant (``eql``, ``ee``, ``pe``, ``mope``) with overrides.

        This is the one place that maps a variant's name to its exploration switches.
        """
        check_algo(algo)
        ee, pe = ALGOS[algo]
        overrides.setdefault("experience_exploration", ee)
        overrides.setdefault("preference_exploration", pe)
        if (overrides["experience_exploration"], overrides["preference_exploration"]) != (ee, pe):
            raise ConfigError(f"algorithm '{algo}' contradicts the exploration switches given with it")
        return cls.from_dict(overrides)

    def replace(self, **changes: Any) -> Config:
        """Return a copy with ``changes`` (flat keys, run settings included) applied (validated)."""
        return self.from_dict({**self.to_dict(), **changes})

    def with_algo(self, algo: str) -> Config:
        """The same settings under another variant (its exploration switches)."""
        d = self.to_dict()
        for key in ("algo", "experience_exploration", "preference_exploration"):
            d.pop(key)
        return Config.for_algo(algo, **d)

    def validate(self) -> None:
        """Raise :class:`ConfigError` naming the first out-of-range hyperparameter."""
        _validate_hyperparameters(self)

    # ------------------------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain, JSON-safe, flat dict of every setting (run settings included), plus the derived ``algo``."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "run"}
        d["hidden_sizes"] = list(self.hidden_sizes)
        d["disc_hidden"] = list(self.disc_hidden)
        run = dataclasses.asdict(self.run)
        run["ref_point"] = None if self.run.ref_point is None else list(self.run.ref_point)
        d.update(run)
        d["algo"] = self.algo
        return d

    @classmethod
    def hyperparameter_names(cls) -> list[str]:
        """Names of the fields that change learning."""
        return [f.name for f in dataclasses.fields(cls) if f.name != "run"]

    @classmethod
    def field_names(cls) -> list[str]:
        """Names of all settable flat keys: hyperparameters, then run settings."""
        return [*cls.hyperparameter_names(), *RunSettings.field_names()]

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Config:
        """Build from a flat dict (a saved config or overrides), the one entry point for dicts and files.
        ``algo`` sets the exploration switches; ``preset`` (see :data:`PRESETS`) sets defaults that the other keys
        override. A config saved by an older mope is read as it ran (:func:`migrate`).
        """
        data = migrate(data)
        names = cls.field_names()
        preset = data.pop("preset", None)
        if preset in (None, "mope") and data.get("env_id") in ENV_DEFAULTS:
            data = {**ENV_DEFAULTS[data["env_id"]], **data}
        if preset is not None:
            data = {**PRESETS[check_preset(preset)], **data}
        algo = data.pop("algo", None)
        for key in data:
            if key not in names:
                raise unknown_key_error(key)
        if algo is not None:
            return cls.for_algo(algo, **data)
        hints = {**typing.get_type_hints(RunSettings), **typing.get_type_hints(cls)}
        for key, value in data.items():
            # ints given as floats ("20000.0") are user slips: coerce where lossless.
            if hints[key] in (int, int | None) and isinstance(value, float) and value.is_integer():
                data[key] = int(value)
        return cls(**data)

    def save(self, path: str | Path) -> None:
        """Write the resolved config as JSON.

        Raises:
            ConfigError: if the file cannot be written (missing permission, a file where a folder should be).
        """
        try:
            Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")
        except OSError as exc:
            raise ConfigError(f"config file '{path}' could not be written: {exc.strerror or exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> Config:
        """Read a config from JSON or YAML."""
        return cls.from_dict(read_config_file(path))


def epsilon_decay_steps_of(config: Config) -> int:
    """Steps over which epsilon decays: ``epsilon_decay_steps``, or when it is None half of ``total_steps`` but at
    least 10k (Deep-Sea-Treasure's 20k steps keep 10k). On minecart's 100k steps, 10k stopped the carts coming home
    once epsilon reached its floor; half the run with the whole run kept did not (docs/results/minecart-probes)."""
    if config.epsilon_decay_steps is not None:
        return config.epsilon_decay_steps
    return half_run_epsilon_decay(config.total_steps)


def half_run_epsilon_decay(total_steps: int) -> int:
    """The default epsilon decay of a ``total_steps`` run: half of it, at least 10k steps."""
    return max(10_000, total_steps // 2)


def buffer_capacity(config: Config) -> int:
    """Transitions the replay buffer holds: ``buffer_size``, or when it is None the whole run (``total_steps``), at
    least 20k (Deep-Sea-Treasure's runs keep 20k) and at most 1M (SB3's default; a longer run keeps its last 1M)."""
    if config.buffer_size is not None:
        return config.buffer_size
    return min(max(config.total_steps, 20_000), 1_000_000)


def migrate(data: dict[str, Any]) -> dict[str, Any]:
    """A saved config of an older mope, brought to today's fields with the values it ran with (a copy).

    A config saved by mope 0.1 (it has the field ``extra``, always empty, and none of 0.2's) gets the ``paper``
    preset's values for the fields it predates, which were 0.1's defaults. A config saved by 0.2.0 (every field
    but those of :data:`LATER_FIELDS`) gets the values of :data:`LATER_FIELDS`. Anything else (today's configs,
    a user's overrides) is returned as it is.
    """
    data = dict(data)
    if "extra" in data and "q_head" not in data:  # saved by mope 0.1: its defaults are the paper preset's
        data = {**PRESETS["paper"], **data}
    data.pop("extra", None)
    later = [k for k in LATER_FIELDS if k not in data]
    if later and "q_head" in data and set(Config.field_names()) - set(data) == set(later):  # saved before these
        data = {**{k: LATER_FIELDS[k] for k in later}, **data}
    return data


def _validate_hyperparameters(self: Config) -> None:
    """The range checks of :meth:`Config.validate`."""
    need = functools.partial(_need, self)
    need(bool(self.env_id), "env_id", "must be a non-empty string")
    need(self.seed >= 0, "seed", "must be an integer >= 0")
    need(self.total_steps >= 1, "total_steps", "must be >= 1")
    need(self.obs_encoding in ENCODINGS, "obs_encoding", f"choose one of {', '.join(ENCODINGS)}")
    need(self.q_head in Q_HEADS, "q_head", f"choose one of {', '.join(Q_HEADS)}")
    need(self.lb_loss in LB_LOSSES, "lb_loss", f"choose one of {', '.join(LB_LOSSES)}")
    need(self.learning_rate_end is None or (_finite(self.learning_rate_end) and self.learning_rate_end > 0),
         "learning_rate_end", "must be > 0 or None")
    for name in ("target_tau", "target_tau_end"):
        tau = getattr(self, name)
        need(tau is None or (_finite(tau) and 0 < tau <= 1), name, "must lie in (0, 1] or be None")
    need(_finite(self.target_tau_anneal_from) and 0 <= self.target_tau_anneal_from < 1, "target_tau_anneal_from",
         "must lie in [0, 1)")
    need(self.max_episode_steps is None or self.max_episode_steps >= 1, "max_episode_steps",
         "must be >= 1 or None")
    need(_finite(self.gamma) and 0.0 < self.gamma <= 1.0, "gamma", "must lie in (0, 1]")
    for name in ("hidden_sizes", "disc_hidden"):
        need(len(getattr(self, name)) >= 1 and all(h >= 1 for h in getattr(self, name)), name,
             "must be one or more positive layer widths")
    for name in ("learning_rate", "disc_learning_rate", "sigma_omega", "per_eps", "pe_count_offset",
                 "reward_scale"):
        need(_finite(getattr(self, name)) and getattr(self, name) > 0, name, "must be > 0")
    capacity = buffer_capacity(self)
    need(capacity >= self.batch_size, "buffer_size", f"must be >= batch_size ({self.batch_size}) or None "
         "(the whole run)")
    need(1 <= self.n_envs <= min(1024, capacity // 2), "n_envs",
         f"must lie in [1, {min(1024, capacity // 2)}] (1024, and half of buffer_size={capacity} at most)")
    for name in ("batch_size", "gradient_steps", "train_freq", "target_update_freq", "n_omega", "n_intervals",
                 "n_components", "n_critics", "return_window"):
        need(getattr(self, name) >= 1, name, "must be >= 1")
    need(epsilon_decay_steps_of(self) >= 1, "epsilon_decay_steps", "must be >= 1 or None (half the run)")
    need(1 <= self.n_step <= 1000, "n_step", "must lie in [1, 1000] (an update runs batch_size x n_step states)")
    for name in ("learning_starts", "lb_homotopy_steps", "demo_pretrain_steps", "demo_roll_in"):
        need(getattr(self, name) >= 0, name, "must be >= 0")
    need(self.demo_episodes >= 1, "demo_episodes", "must be >= 1")
    for name in ("lb_weight", "per_alpha", "mi_alpha", "component_loss_weight", "component_anchor_weight",
                 "demo_margin", "demo_loss_weight", "demo_label_weight"):
        need(_finite(getattr(self, name)) and getattr(self, name) >= 0, name, "must be >= 0")
    need(self.reward_norm is None or (_finite(self.reward_norm) and self.reward_norm > 0), "reward_norm",
         "must be > 0 or None")
    need(self.epsilon_repeat_mu is None or (_finite(self.epsilon_repeat_mu) and self.epsilon_repeat_mu > 1),
         "epsilon_repeat_mu", "must be > 1 (the exponent of a zeta distribution) or None (epsilon-greedy)")
    need(self.seen_bound_margin is None or (_finite(self.seen_bound_margin) and self.seen_bound_margin >= 0),
         "seen_bound_margin", "must be >= 0 or None")
    need(not self.consistent_bellman or (one_pass_target(self) and self.n_step == 1), "consistent_bellman",
         "needs the convex head's one-step target (q_head=convex, n_critics=1, double_q, envelope_prefs=own, n_step=1)")
    need(self.max_grad_norm is None or (_finite(self.max_grad_norm) and self.max_grad_norm > 0),
         "max_grad_norm", "must be > 0 or None")
    for name in ("epsilon_start", "epsilon_end", "per_beta_start", "relabel_broad", "return_mix", "demo_batch_share"):
        need(_finite(getattr(self, name)) and 0.0 <= getattr(self, name) <= 1.0, name, "must lie in [0, 1]")
    need(self.envelope_prefs in ENVELOPE_PREFS, "envelope_prefs", f"choose one of {', '.join(ENVELOPE_PREFS)}")


def read_config_file(path: str | Path) -> dict[str, Any]:
    """The mapping of settings in a JSON or YAML config file, as written (unresolved)."""
    path = Path(path)
    text = read_text_file(path, "config file", ConfigError)
    try:
        data = (load_yaml(text) if path.suffix in (".yaml", ".yml") else json.loads(text)) or {}
        check_size(data)
    except Exception as exc:  # noqa: BLE001 - any parse failure is the user's file
        raise ConfigError(f"config file '{path}' could not be parsed: {_parse_problem(exc)}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"config file '{path}' must hold a mapping of settings")
    return data


#: A settings file (a config or a sweep spec) may hold this many values in all, each alias counted where it is used.
MAX_FILE_VALUES = 100_000
#: And at most this many bytes.
MAX_FILE_BYTES = 10_000_000


def read_text_file(path: Path, what: str, error: type[ConfigError]) -> str:
    """The text of a settings file, or ``error`` saying it does not exist, is a folder, is too big or unreadable."""
    try:
        if path.is_dir():
            raise error(f"{what} '{path}' is a folder, not a file")
        if not path.exists():
            raise error(f"{what} '{path}' does not exist")
        if not path.is_file():
            raise error(f"{what} '{path}' is not a regular file")
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise error(f"{what} '{path}' holds {size} bytes; a settings file may hold {MAX_FILE_BYTES} at most")
        return path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise error(f"{what} '{path}' could not be read: {reason}") from None


class FileTooBigError(ValueError):
    """A settings file expands to too many values (a parse problem of :func:`read_config_file`)."""


#: YAML 1.2's floats, which PyYAML's YAML 1.1 resolver misses without a dot: ``3e-4`` is a string there.
YAML_FLOAT = re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""", re.X)


def load_yaml(text: str) -> Any:
    """``yaml.safe_load(text)`` with YAML 1.2's floats (``learning_rate: 3e-4`` is a number, not the string PyYAML
    reads), refusing a document that aliases expand beyond :data:`MAX_FILE_VALUES` values (a "billion laughs"
    file: a few hundred bytes of nested aliases that would take minutes and gigabytes to format) or that holds
    itself (a recursive alias)."""
    import yaml

    class Loader(yaml.SafeLoader):
        pass

    Loader.add_implicit_resolver("tag:yaml.org,2002:float", YAML_FLOAT, list("-+0123456789."))
    data = yaml.load(text, Loader=Loader)  # noqa: S506 - a SafeLoader
    check_size(data)
    return data


def check_size(data: Any) -> None:
    """Raise :class:`FileTooBigError` if ``data`` expands to more than :data:`MAX_FILE_VALUES` values or contains
    itself. Each distinct list or mapping is visited once, so the check takes time linear in the file."""
    sizes: dict[int, int] = {}

    def size(x: Any, open_: set[int]) -> int:
        if not isinstance(x, (list, dict)):
            return 1
        key = id(x)
        if key in open_:
            raise FileTooBigError("a YAML alias refers to a value that contains it (a recursive value)")
        if key not in sizes:
            open_.add(key)
            items = list(x.keys()) + list(x.values()) if isinstance(x, dict) else x
            total = 1
            for item in items:
                total += size(item, open_)
                if total > MAX_FILE_VALUES:
                    raise FileTooBigError(f"it expands to more than {MAX_FILE_VALUES} values (YAML anchors and "
                                          "aliases nested inside each other); write the values out")
            open_.discard(key)
            sizes[key] = total
        return sizes[key]

    size(data, set())


def check_algo(algo: str) -> str:
    """Return ``algo`` if it names a variant, else raise a :class:`ConfigError` with the closest name."""
    if algo not in ALGOS:
        raise ConfigError(f"unknown algorithm '{algo}'{suggest(algo, ALGOS)}; choose one of {', '.join(ALGOS)}")
    return algo


def unknown_key_error(key: str) -> ConfigError:
    """The error for a key that is not a :class:`Config` field, with the closest field name when one is close."""
    names = Config.field_names()
    hint = suggest(key, names) or "; valid keys are the fields of mope.Config, e.g. gamma, n_omega, sigma_omega"
    return ConfigError(f"unknown config key '{key}'{hint}")


#: Fields that also take ``64,64`` for a list of integers.
_INT_LIST_FIELDS = ("hidden_sizes", "disc_hidden")


def parse_set(items: Sequence[str] | None, check_keys: bool = False,
              error: type[ConfigError] = ConfigError) -> dict[str, Any]:
    """``KEY=VALUE`` strings (every command's ``--set``, a sweep's included) as a dict; the one ``--set`` parser.

    VALUE is read as JSON when it parses (numbers, ``1e-3`` included, lists, true/false, null), else as YAML if it
    is a flow list or mapping (``[8, 8]``, ``{a: 1}``), else kept as the string (``demos=`` is the empty
    string); ``hidden_sizes`` and ``disc_hidden`` also take ``256,256``. A dash in KEY reads as an underscore.
    Types and ranges are checked later, by :class:`Config`.

    Args:
        items: The ``KEY=VALUE`` strings.
        check_keys: Refuse a KEY that is no field of :class:`Config` (``preset`` must name a preset).
        error: The error class to raise (a sweep raises its own).

    Raises:
        ConfigError: An item is not ``KEY=VALUE``, a list of integers does not parse, a YAML value expands beyond
            :data:`MAX_FILE_VALUES` values; with ``check_keys``, KEY is no field.
    """
    out: dict[str, Any] = {}
    names = Config.field_names()
    for item in items or ():
        if "=" not in item:
            raise error(f"--set '{item}' is not KEY=VALUE")
        key, raw = item.split("=", 1)
        key = key.strip().replace("-", "_")
        if check_keys and key == "preset":
            out[key] = check_preset(raw.strip())
            continue
        if check_keys and key not in names:
            raise unknown_key_error(key)
        out[key] = _parse_value(key, raw, error)
    return out


def one_pass_target(cfg: Config) -> bool:
    """Whether eq. 4's target takes the convex head's fast path (``ConvexQNetwork.double_q_values``): one head,
    double Q, no envelope over other preferences (the defaults)."""
    return cfg.q_head == "convex" and cfg.n_critics == 1 and cfg.double_q and cfg.envelope_prefs == "own"


def _nullable(key: str) -> bool:
    """Whether the setting ``key`` takes None (its type hint is ``X | None``)."""
    hints = {**typing.get_type_hints(Config), **typing.get_type_hints(RunSettings)}
    return type(None) in typing.get_args(hints.get(key))


def _parse_value(key: str, raw: str, error: type[ConfigError]) -> Any:
    """One ``--set`` value: JSON, else YAML, else the string (a list of integers for :data:`_INT_LIST_FIELDS`);
    Python's ``None`` (or ``none``) is null for a setting that takes null, as people type it."""
    import yaml

    if raw.strip() in ("None", "none") and _nullable(key):
        return None
    try:
        return json.loads(raw)
    except json.JSONDecodeError:
        pass
    try:
        value = load_yaml(raw)
    except yaml.YAMLError:
        value = raw
    except Exception as exc:  # noqa: BLE001 - an alias bomb or a recursive value
        raise error(f"--set {key}: {_parse_problem(exc)}") from None
    if not isinstance(value, list | dict):  # a plain word stays the word: "demos=" is "", "yes" is not True
        value = raw
    if isinstance(value, str) and key in _INT_LIST_FIELDS:
        try:
            return [int(x) for x in raw.split(",")]
        except ValueError:
            raise error(f"--set {key}={raw!r} is not a comma-separated list of integers") from None
    return value


def parse_overrides(items: Sequence[str] | None) -> dict[str, Any]:
    """The config overrides of a command's ``--set``: :func:`parse_set` with every KEY checked."""
    return parse_set(items, check_keys=True)


def _parse_problem(exc: Exception) -> str:
    """A short description of a JSON or YAML parse error with its line and column."""
    problem = getattr(exc, "problem", None)  # yaml.MarkedYAMLError
    mark = getattr(exc, "problem_mark", None)
    if problem and mark is not None:
        return f"{problem} at line {mark.line + 1}, column {mark.column + 1}"
    if isinstance(exc, RecursionError):
        return "it nests lists or mappings too deeply"
    return str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__


_HYPERPARAMETER_NAMES = frozenset(Config.hyperparameter_names())
_RUN_NAMES = frozenset(RunSettings.field_names())
