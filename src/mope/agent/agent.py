"""The agents: Envelope Q-learning (EQL) and MoPE = EQL + experience exploration (EE) + preference exploration (PE).

One class, :class:`MoPE`, implements all four variants of the paper's Fig. 2; the config's two switches
``experience_exploration`` and ``preference_exploration`` select them, and :class:`EQL` is MoPE with both off.

The seams are Stable-Baselines3's. One environment step (:meth:`MoPE.collect_step`):

1. act epsilon-greedily (:meth:`MoPE.act`) under the episode's preference ``omega_b`` and store
   ``(s, omega_b, a, r, s')``; at each episode start, ``omega_b`` is drawn uniformly (EQL) or by preference
   exploration (PE).

One update (:meth:`MoPE.update`), top to bottom:

2. sample a batch, with prioritized replay;
3. give each transition N_omega preferences (:meth:`MoPE.relabel`): uniform ones shared by the batch (EQL, as
   Yang et al.), or ``omega_b`` and its neighbours within sigma_omega (EE);
4. the envelope target y and the loss L = L^A + L^B (eq. 4); one Adam step;
5. new priorities: the preference-interval TD error (eq. 5), plus, with EE, alpha times the discriminator's
   mutual-information term (eq. 6-7); then one discriminator step.

Housekeeping (:meth:`MoPE.end_step`): the target network (Polyak averaging with ``target_tau``, by default, or a
hard copy every ``target_update_freq`` steps) and the learning-rate schedule.
The loop that strings these together, with evaluation, progress, checkpoints and logs as callbacks, is
:func:`mope.agent.runner.train`.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import math
from collections.abc import Callable, Iterator
from typing import Any, NamedTuple, TypeVar

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from mope.agent import losses, optim, targets
from mope.agent.agent_state import resolve_device
from mope.agent.base import BaseAgent, Episode, linear_schedule
from mope.agent.demonstrations import (
    Demonstrations,
    collect_demonstrations,
    default_demonstrations,
    load_demonstrations,
)
from mope.agent.networks import ConvexQNetwork, Discriminator, make_q_network
from mope.agent.replay import Batch, ReplayBuffer
from mope.config import Config, buffer_capacity, check_algo
from mope.envs import check_env_fits, make_env
from mope.errors import ConfigError, MopeError
from mope.preferences import PreferenceSampler, sample_neighbours, sample_simplex

__all__ = ["EQL", "MoPE", "TrainingDivergedError", "agent_class", "linear_schedule", "make_agent", "resolve_device",
           "return_bounds"]


class MarginRows(NamedTuple):
    """The rows of DQfD's margin loss J_E in a batch: the demonstrator's action, which rows, and their weight."""

    actions: torch.Tensor
    mask: torch.Tensor
    weight: torch.Tensor | float

    def repeat(self, heads: int) -> MarginRows:
        """Each row ``heads`` times in a row (the convex head's rows ``b * H + h``)."""
        return MarginRows(*(t.repeat_interleave(heads, dim=0) if torch.is_tensor(t) else t for t in self))


def margin_rows(cfg: Config, buffer: ReplayBuffer, indices: np.ndarray, actions: torch.Tensor,
                demo: torch.Tensor) -> MarginRows | None:
    """J_E's rows in a batch (``indices``, taken ``actions``, ``demo`` the rows in kept slots): on demonstrations
    the demonstrator's action with weight ``demo_loss_weight``; with ``demo_label_weight``, on the learner's own
    transitions their DAgger labels (:func:`mope.agent.demonstrations.label_actions`); None if J_E is off."""
    if cfg.demo_label_weight > 0:
        expert = torch.as_tensor(buffer.expert_actions[indices], device=actions.device)
        labelled = ~demo & (expert >= 0)
        weight = cfg.demo_loss_weight * demo.float() + cfg.demo_label_weight * labelled.float()
        return MarginRows(torch.where(demo, actions, expert.clamp(min=0)), demo | labelled, weight)
    if buffer.reserved and cfg.demo_loss_weight > 0:
        return MarginRows(actions, demo, cfg.demo_loss_weight)
    return None


class TrainingDivergedError(MopeError):
    """A loss, Q-value or priority became NaN or infinite."""


def return_bounds(env: gym.Env, gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-objective bounds of any discounted return, from the environment's ``reward_space``.

    A return has at least one reward, so with per-step rewards in ``[lo, hi]``: it is at least ``lo`` when
    ``lo >= 0`` and at least ``lo / (1 - gamma)`` otherwise; symmetrically for the upper bound. Infinite bounds
    stay infinite (no clamping). On Deep-Sea-Treasure the time objective gets ``[-1/(1-gamma), -1]``.
    """
    space = env.unwrapped.reward_space
    lo = np.asarray(space.low, dtype=np.float64).reshape(-1)
    hi = np.asarray(space.high, dtype=np.float64).reshape(-1)
    horizon = 1.0 / (1.0 - gamma) if gamma < 1 else np.inf
    with np.errstate(invalid="ignore", over="ignore"):
        q_lo = np.where(lo >= 0, lo, lo * horizon)
        q_hi = np.where(hi <= 0, hi, hi * horizon)
    return np.nan_to_num(q_lo, nan=-np.inf), np.nan_to_num(q_hi, nan=np.inf)


def largest_reward(env: gym.Env) -> float:
    """The largest per-step reward magnitude, over all objectives, that ``env``'s ``reward_space`` allows
    (infinite when it has none, or an unbounded one)."""
    space = getattr(env.unwrapped, "reward_space", None)
    if space is None:
        return math.inf
    return float(np.max(np.abs(np.concatenate([np.ravel(space.low), np.ravel(space.high)]))))


@functools.lru_cache(maxsize=64)
def _largest_reward_of(env_id: str) -> float:
    return largest_reward(make_env(env_id))


def learner_reward_scale(largest: float, reward_scale: float, reward_norm: float | None) -> float:
    """The factor every reward is multiplied by inside the learner: ``reward_scale``, times ``reward_norm / R``
    when the largest per-step reward magnitude ``R`` that the environment's ``reward_space`` allows (over all
    objectives, after ``reward_scale``) exceeds ``reward_norm``.

    ``largest`` is :func:`largest_reward` of the environment (before ``reward_scale``). One factor for all
    objectives, so every preference ranks every return as before: no greedy action and no reported value changes
    meaning (values are reported in the environment's units). An unbounded or missing reward space leaves
    ``reward_scale`` alone. Deep-Sea-Treasure (``R`` = 23.7), the robot game (10), resource-gathering, four-room and
    minecart (1.5 at most) are at or below a ``reward_norm`` of 25, so their factor is exactly 1; the concave and
    mirrored maps (124) get 25 / 124.
    """
    if reward_norm is None:
        return reward_scale
    bound = largest * reward_scale
    if not math.isfinite(bound) or bound <= reward_norm:
        return reward_scale
    return reward_scale * (reward_norm / bound)


def without_inert_reward_norm(config: dict[str, Any]) -> dict[str, Any]:
    """A saved config's mapping with ``reward_norm`` set to None where it does not act (the environment's rewards
    never exceed it, so the learner's factor is ``reward_scale`` exactly): such a run is the same run, bit for bit,
    as one saved before the setting existed (those read None). Finished runs are compared through this."""
    norm, env_id = config.get("reward_norm"), config.get("env_id")
    if norm is None or not isinstance(env_id, str):
        return config
    try:
        scale = learner_reward_scale(_largest_reward_of(env_id), float(config.get("reward_scale", 1.0)), float(norm))
    except Exception:  # noqa: BLE001 - an env that cannot be built here: compare the settings as written
        return config
    return {**config, "reward_norm": None} if scale == config.get("reward_scale", 1.0) else config


def polyak_weight(config: Config, step: int) -> float | None:
    """The target network's Polyak weight at ``step``: ``target_tau``, or annealed to ``target_tau_end`` on a
    cosine that starts at the fraction ``target_tau_anneal_from`` of the run and ends with it (None: the hard copy).
    """
    if config.target_tau is None or config.target_tau_end is None:
        return config.target_tau
    start = round(config.target_tau_anneal_from * config.total_steps)
    if step <= start:  # exactly target_tau, so a run is the constant weight's bit for bit up to here
        return config.target_tau
    return cosine_schedule(config.target_tau, config.target_tau_end, config.total_steps - start, step - start)


def cosine_schedule(start: float, end: float, duration: int, step: int) -> float:
    """Cosine interpolation from ``start`` to ``end`` over ``duration`` steps, then constant."""
    frac = min(1.0, step / max(1, duration))
    return end + 0.5 * (start - end) * (1.0 + math.cos(math.pi * frac))


def crossed(step: int, n: int, every: int) -> bool:
    """Whether the last ``n`` env steps, ending at ``step``, passed a multiple of ``every`` (``every`` > 0)."""
    return step // every > (step - n) // every


def update_statistics(loss: torch.Tensor, parts: dict[str, torch.Tensor], td: torch.Tensor, q: torch.Tensor,
                      w: torch.Tensor, bonus: torch.Tensor | None, disc_loss: torch.Tensor | None,
                      reward_scale: float = 1.0) -> dict[str, float]:
    """What one update reports: the loss and its parts, |TD| (eq. 5), the scalarised Q of the taken actions,
    the MI bonus (eq. 6) and the discriminator's loss. |TD| and Q are in the environment's units (divided by
    ``reward_scale``); the losses are in the learner's. One host transfer for all of them."""
    q_scal = losses.objective_sum(w * q)
    values = torch.stack([loss.detach(), *(v.detach().mean() for v in parts.values()), td.abs().mean(),
                          q_scal.mean(), q_scal.max(),
                          *(() if bonus is None or disc_loss is None else (bonus.mean(), disc_loss.detach()))]).tolist()
    stats = {"loss": values[0], **dict(zip(parts, values[1:], strict=False))}
    k = 1 + len(parts)
    stats.update(td_abs=values[k] / reward_scale, q_mean=values[k + 1] / reward_scale,
                 q_max=values[k + 2] / reward_scale)
    if bonus is not None and disc_loss is not None:
        stats["mi_bonus"], stats["disc_loss"] = values[k + 3], values[k + 4]
    return stats


def check_finite(loss: torch.Tensor, q: torch.Tensor, y: torch.Tensor, step: int) -> None:
    """Raise :class:`TrainingDivergedError` naming the first non-finite quantity of a failed update."""
    if torch.isfinite(loss):
        return
    if not torch.isfinite(q).all():
        what = f"a Q-value is {q[~torch.isfinite(q)][0].item()}"
    elif not torch.isfinite(y).all():
        what = f"an envelope target is {y[~torch.isfinite(y)][0].item()}"
    else:
        what = f"the EQL loss is {loss.item()}"
    raise TrainingDivergedError(f"training diverged at step {step}: {what}")


def denormals_are_flushed() -> bool:
    """Whether the CPU flushes denormal floats to zero now (probed: a denormal times 1 is then 0)."""
    return bool(torch.tensor([1e-39]).mul_(1.0)[0] == 0)


@contextlib.contextmanager
def flushed_denormals() -> Iterator[None]:
    """Flush denormal floats (below 1.2e-38) to zero on the CPU while the block runs, then restore the mode.

    Adam's second moments of weights whose gradients are (nearly) zero, such as a dead ReLU unit's, decay
    geometrically into the denormal range, where x86 arithmetic is many times slower: on Deep-Sea-Treasure
    the Q-network's Adam step took 0.98 ms with denormals and 0.31 ms without (``benchmarks/update_sections.py``).
    Values that small are below anything the update can resolve (float32's epsilon at 1 is 1.2e-7).
    """
    was = denormals_are_flushed()
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        if not was:
            torch.set_flush_denormal(False)


_F = TypeVar("_F", bound=Callable[..., Any])


def with_flushed_denormals(fn: _F) -> _F:
    """Run ``fn`` under :func:`flushed_denormals`."""
    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with flushed_denormals():
            return fn(*args, **kwargs)
    return wrapper  # type: ignore[return-value]


def demonstrations_for(cfg: Config, env: gym.Env) -> Demonstrations | None:
    """The demonstrations ``cfg.demos`` names: ``"scripted"``, ``cfg.demo_episodes`` episodes of each scripted
    policy registered for the env (each at its own preference range, reset seeds away from training's); a path,
    the episodes in that file; ``""``, None."""
    if not cfg.demos:
        return None
    spec = check_env_fits(env, cfg.env_id)
    if cfg.demos != "scripted":
        return load_demonstrations(cfg.demos, spec.obs_space.shape, spec.n_actions, spec.n_objectives)
    sources = default_demonstrations(cfg.env_id)
    if not sources:
        raise ConfigError(f"demos='scripted': environment '{cfg.env_id}' has no scripted policy; give a file of "
                          "episodes instead (demos=PATH.npz, see mope.agent.demonstrations.save_demonstrations)")
    demo_env = make_env(cfg.env_id, cfg.max_episode_steps)
    return Demonstrations.concatenate([
        collect_demonstrations(demo_env, name, cfg.demo_episodes, pref_range,
                               seed=1_000_000 * (k + 1) + 10_000 * cfg.seed, roll_in=cfg.demo_roll_in)
        for k, (name, pref_range) in enumerate(sources)])


def add_demonstrations(buffer: ReplayBuffer, cfg: Config, env: gym.Env) -> Demonstrations | None:
    """Write the config's demonstrations (:func:`demonstrations_for`) into the first slots of ``buffer`` and keep
    them there for good (DQfD); their updates add the margin loss J_E. Checks that DAgger's labels
    (``demo_label_weight``) have scripted policies to come from. Returns the demonstrations (None if the
    config has none)."""
    if cfg.demo_label_weight and not default_demonstrations(cfg.env_id):
        raise ConfigError(f"demo_label_weight={cfg.demo_label_weight}: environment '{cfg.env_id}' has no "
                          "scripted policy to label the learner's states; set demo_label_weight=0")
    demos = demonstrations_for(cfg, env)
    if demos is None:
        return None
    if len(demos) > buffer_capacity(cfg) // 2:
        raise ConfigError(f"the demonstrations hold {len(demos)} transitions, more than half of "
                          f"buffer_size={buffer_capacity(cfg)}; raise buffer_size or use fewer demo_episodes")
    buffer.add_batch(demos.obs, demos.prefs, demos.actions, demos.rewards, demos.next_obs, demos.terminated,
                     demos.dones)
    buffer.keep_written()
    return demos


def relabel_preferences(c: Config, acting_prefs: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    """Step 3 of an update: preferences of the training rows, ``(B, N_omega, m)``.

    EQL: N_omega uniform preferences shared by the whole batch (Yang et al. 2019); with ``return_mix`` (the
    default) the first is the transition's own preference instead, the row that learns the behaviour's return.
    EE (sec. 3, similar preference exploration): the transition's own ``omega_b`` plus neighbours within
    sigma_omega; with ``relabel_broad`` > 0, that share of the N_omega rows is drawn uniformly from the simplex.
    """
    b = len(acting_prefs)
    if not c.experience_exploration:
        shared = sample_simplex(c.n_omega, m, rng)
        rows = np.repeat(shared[None], b, axis=0)
        if c.return_mix:  # the row that learns the behaviour's return is the transition's own preference
            rows[:, 0] = acting_prefs
        return rows
    n_broad = min(c.n_omega - 1, round(c.n_omega * c.relabel_broad))
    near = sample_neighbours(acting_prefs, c.n_omega - 1 - n_broad, c.sigma_omega, rng)
    rows = [acting_prefs[:, None, :].astype(np.float64), near]
    if n_broad:
        rows.append(sample_simplex(b * n_broad, m, rng).reshape(b, n_broad, m))
    return np.concatenate(rows, axis=1)


def resolve_config(cls: type[MoPE], env: gym.Env | str, config: Config | None, overrides: dict[str, Any]) -> Config:
    """An agent's config: the given one (checked against the class's variant) or the class's variant, plus
    overrides; the env's id comes from ``env``."""
    if isinstance(env, str):
        overrides = {"env_id": env, **overrides}
    elif env.spec is not None:
        overrides = {"env_id": env.spec.id, **overrides}
    elif "env_id" not in overrides and (config is None or config.env_id == Config().env_id):
        overrides = {"env_id": type(env.unwrapped).__name__, **overrides}  # a hand-built env: name its class
    if config is None:
        return Config.for_algo(check_algo(cls.variant), **overrides)
    cfg = config.replace(**overrides) if overrides else config
    if cls.strict_variant and cfg.algo != cls.variant:
        raise ConfigError(f"{cls.__name__} needs a config of algorithm '{cls.variant}', got '{cfg.algo}'; "
                          f"use Config.for_algo('{cls.variant}', ...) or mope.make_agent('{cfg.algo}', ...)")
    return cfg


class MoPE(BaseAgent):
    """Multi-objective RL with Preference Exploration (and its ablations, including plain EQL).

    Args:
        env: A Gymnasium/MO-Gymnasium environment, or its id.
        config: A :class:`~mope.config.Config`; default: the class's variant (``mope``; ``eql`` for EQL).
        **overrides: Any ``Config`` field, e.g. ``n_omega=64, sigma_omega=0.04, mi_alpha=0.1``.

    Example:
        >>> agent = MoPE("deep-sea-treasure-v0", total_steps=20_000, seed=0)
        >>> agent.train()
        >>> agent.act(obs, [0.3, 0.7])
    """

    #: The variant this class builds when no config is given.
    variant: str = "mope"
    #: Whether a config must name exactly that variant (MoPE runs any of the four; EQL only ``eql``).
    strict_variant: bool = False

    @classmethod
    def class_for(cls, algo: str) -> type[MoPE]:
        """The class that :meth:`load` builds for a checkpoint of ``algo`` (:func:`agent_class`)."""
        return agent_class(algo)

    def __init__(self, env: gym.Env | str, config: Config | None = None, **overrides: Any) -> None:
        self.config = cfg = resolve_config(type(self), env, config, overrides)
        self.env = make_env(cfg.env_id, cfg.max_episode_steps) if isinstance(env, str) else env
        spec = check_env_fits(self.env, cfg.env_id)
        #: The ``n_envs`` training environments (``env`` is the first), stepped together by :meth:`collect_step`.
        self.envs = [self.env] + [copy.deepcopy(self.env) for _ in range(cfg.n_envs - 1)]
        self.n_actions, self.m = spec.n_actions, spec.n_objectives
        self.obs_shape = spec.obs_space.shape or ()

        if cfg.run.torch_threads:
            torch.set_num_threads(cfg.run.torch_threads)
        self.device = resolve_device(cfg.run.device)
        self.rng = np.random.default_rng(cfg.seed)
        torch.manual_seed(cfg.seed)

        def q_network() -> nn.Module:
            return make_q_network(spec.obs_space, self.n_actions, self.m, cfg.hidden_sizes, cfg.obs_encoding,
                                  cfg.q_head, cfg.n_components, cfg.n_critics, cfg.layer_norm).to(self.device)

        self.q_net = q_network()
        self.target_net = q_network()
        self.target_net.load_state_dict(self.q_net.state_dict())
        self.target_net.requires_grad_(False)
        self._q_params, self._target_params = list(self.q_net.parameters()), list(self.target_net.parameters())
        self.optimizer = torch.optim.Adam(self._q_params, lr=cfg.learning_rate, fused=True)

        self.pref_sampler = PreferenceSampler(self.m, cfg.n_intervals, cfg.preference_exploration,
                                              cfg.pe_count_offset)
        self.discriminator: Discriminator | None = None
        self.disc_optimizer: torch.optim.Optimizer | None = None
        if cfg.experience_exploration:
            self.discriminator = Discriminator(spec.obs_space, self.pref_sampler.partition.n_cells,
                                               cfg.disc_hidden, cfg.obs_encoding).to(self.device)
            self.disc_optimizer = torch.optim.Adam(self.discriminator.parameters(), lr=cfg.disc_learning_rate,
                                                   fused=True)

        self.q_low, self.q_high = return_bounds(self.env, cfg.gamma)
        self.reward_scale = learner_reward_scale(largest_reward(self.env), cfg.reward_scale, cfg.reward_norm)
        self.set_target_clamp()
        obs_dtype = np.float32 if not isinstance(spec.obs_space, gym.spaces.Discrete) else np.int64
        self.buffer = ReplayBuffer(buffer_capacity(cfg), self.obs_shape, self.m, cfg.per, obs_dtype)
        self.buffer.stride = cfg.n_envs
        self.observe_demonstrations(add_demonstrations(self.buffer, cfg, self.env))
        self.global_step = 0
        #: Episodes finished, and started (the next reset's seed is ``seed + episodes_started``).
        self.episodes = 0
        self.episodes_started = 0
        self.ended_episodes = []
        #: Training wall seconds before the current ``train`` call (carried across resumes), evaluations included.
        self.wall_s = 0.0
        #: Of which evaluating (carried across resumes too).
        self.eval_seconds = 0.0
        # The episode in progress in each env (kept across ``train`` calls and in resumable checkpoints): its
        # reset seed, preference, current observation and the actions taken so far (replayed on load to restore
        # the env), and, with return_mix, its buffer slots and which of its actions were greedy. None: not begun.
        self._episodes: list[Episode] | None = None
        #: Statistics of the latest update (what :meth:`update` returned).
        self.last_losses: dict[str, float] = {}
        #: Solutions of the latest evaluation in :meth:`train` (uniform preference set), or None.
        self.last_solutions = None

    # ---------------------------------------------------------------------------------------------------------
    # learning
    # ---------------------------------------------------------------------------------------------------------
    def learn_step(self) -> dict[str, float] | None:
        """Steps 2-5, ``gradient_steps`` times, each followed by the Polyak update of the target network, once
        learning has started and every ``train_freq``-th collection step; the last update's statistics."""
        c = self.config
        if self.global_step <= c.learning_starts or len(self.buffer) < c.batch_size \
                or (self.global_step // c.n_envs) % c.train_freq:
            return None
        stats = None
        for _ in range(c.gradient_steps):
            stats = self.update()
            self._polyak()
        return stats

    def pretrain(self) -> dict[str, float] | None:
        """DQfD's pre-training: ``demo_pretrain_steps`` updates (each with its Polyak step) on the demonstrations
        alone, before the first env step; the last update's statistics."""
        stats = None
        for _ in range(self.config.demo_pretrain_steps if self.buffer.reserved else 0):
            stats = self.update()
            self._polyak()
        return stats

    def _polyak(self) -> None:
        tau = polyak_weight(self.config, self.global_step)
        if tau is not None:
            with torch.no_grad():
                torch._foreach_lerp_(self._target_params, self._q_params, tau)

    def end_step(self) -> None:
        """Housekeeping after a collection step: the hard target-network copy (every ``target_update_freq`` env
        steps, when ``target_tau`` is None) and the learning-rate schedule."""
        c = self.config
        if c.target_tau is None and crossed(self.global_step, c.n_envs, c.target_update_freq):
            self.target_net.load_state_dict(self.q_net.state_dict())
        if c.learning_rate_end is not None:
            for group in self.optimizer.param_groups:
                group["lr"] = cosine_schedule(c.learning_rate, c.learning_rate_end, c.total_steps, self.global_step)

    def relabel(self, acting_prefs: np.ndarray) -> np.ndarray:
        """Step 3: preferences of the training rows, ``(B, N_omega, m)`` (:func:`relabel_preferences`)."""
        return relabel_preferences(self.config, acting_prefs, self.m, self.rng)

    @with_flushed_denormals
    def update(self) -> dict[str, float]:
        """Steps 2-5 of the module docstring: one gradient step on a sampled batch; returns its statistics.
        Denormal floats are flushed to zero meanwhile (:func:`flushed_denormals`)."""
        c = self.config
        batch = self.buffer.sample(c.batch_size, self.rng, self._per_beta(),                      # 2
                                   round(c.batch_size * c.demo_batch_share))
        obs, actions, acting = self._tensor(batch.obs), self._tensor(batch.actions, torch.int64), \
            self._tensor(batch.prefs)
        w = self._tensor(self.relabel(batch.prefs))                                               # 3
        demo = self._tensor(batch.indices < self.buffer.reserved, torch.bool)  # demonstrations (kept slots)
        y = self._envelope_target(batch, w, acting, demo)                                         # 4: eq. 4
        rows = margin_rows(c, self.buffer, batch.indices, actions, demo)  # J_E's rows (DQfD; DAgger labels)
        feats = self.q_net.encoder(obs)  # every network's encoder is the same parameter-free function: encode once
        q, loss_rows, parts = self._eql_loss(obs, actions, w, y, rows, feats)                      # 4: eq. 4 + J_E
        loss = (self._tensor(batch.weights) * loss_rows).mean()
        check_finite(loss, q, y, self.global_step)
        bonus, disc_loss = self._discriminator_loss(obs, batch.prefs, feats)                       # 5: eq. 6
        self._gradient_step(loss, disc_loss)  # 4, and 5's discriminator step: one Adam step each
        td = losses.preference_interval_td(q.detach(), y, w)                                      # 5: eq. 5
        self._set_priorities(batch, losses.priority(td, bonus, c.mi_alpha, c.per_eps, c.per_alpha))  # 5: eq. 7
        self.last_losses = update_statistics(loss, parts, td, q.detach(), w, bonus, disc_loss, self.reward_scale)
        return self.last_losses

    def _eql_loss(self, obs: torch.Tensor, actions: torch.Tensor, w: torch.Tensor, y: torch.Tensor,
                  rows: MarginRows | None, feats: torch.Tensor | None = None
                  ) -> tuple[torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
        """Q(s, a, w) of the taken actions and the per-transition loss: eq. 4 (with the L^B weight or homotopy of
        the config), plus the convex head's component loss and, on ``rows`` (:func:`margin_rows`), DQfD's margin
        loss J_E at the transition's own preference (row 0)."""
        c = self.config
        heads = 1
        if isinstance(self.q_net, ConvexQNetwork):  # every head learns the same targets (rows b*H + h)
            comps = self.q_net.components(obs, feats)  # (B, H, A, C, m)
            b, heads, _, n_comp, m = comps.shape
            taken = comps.gather(2, actions.view(b, 1, 1, 1, 1).expand(b, heads, 1, n_comp, m)).view(
                b * heads, n_comp, m)  # (B*H, C, m): the taken action's components
            if heads > 1:
                actions, w, y = (t.repeat_interleave(heads, dim=0) for t in (actions, w, y))
                rows = rows.repeat(heads) if rows is not None else None
            q = self.q_net.select_one(taken, w)  # (B*H, N, m)
            comp_loss = losses.component_loss(taken, y, c.component_anchor_weight)
            if rows is not None:  # w^T Q(s, a, w) of every action at the demonstrated preference (row 0)
                scalar = torch.einsum("bm,bacm->bac", w[:, 0], comps.flatten(0, 1)).amax(dim=2)
        else:
            q_all = self.q_net.forward_prefs(obs, w)
            q = losses.taken_action_q(q_all, actions)
            comp_loss = None
            if rows is not None:
                scalar = torch.einsum("bam,bm->ba", q_all[:, 0], w[:, 0])
        margin = None
        if rows is not None:
            margin = losses.large_margin_loss(scalar, rows.actions, c.demo_margin, rows.mask)
        if c.lb_homotopy_steps:  # Yang et al.'s homotopy: (1 - lambda) L^A + lambda L^B, lambda rising to lb_weight
            lam = c.lb_weight * min(1.0, self.global_step / c.lb_homotopy_steps)
            _, l_a, l_b = losses.eql_loss(q, y, w, lb_loss=c.lb_loss)
            loss_rows = (1.0 - lam) * l_a + lam * l_b
        else:
            loss_rows, l_a, l_b = losses.eql_loss(q, y, w, c.lb_weight, c.lb_loss)
        parts = {"loss_a": l_a, "loss_b": l_b}
        if comp_loss is not None:
            loss_rows = loss_rows + losses.weighted(c.component_loss_weight, comp_loss)
            parts["loss_components"] = comp_loss
        if margin is not None:
            loss_rows = loss_rows + losses.weighted(rows.weight, margin)
            parts["loss_margin"] = margin
        if heads > 1:  # per transition: the heads' losses summed, their statistics and Q averaged
            loss_rows = loss_rows.view(-1, heads).sum(1)
            parts = {k: v.view(-1, heads).mean(1) for k, v in parts.items()}
            q = q.view(-1, heads, *q.shape[1:]).mean(1)
        return q, loss_rows, parts

    def _per_beta(self) -> float:
        c = self.config
        return linear_schedule(c.per_beta_start, 1.0, c.total_steps, self.global_step)

    @torch.inference_mode()
    def _envelope_target(self, batch: Batch, w: torch.Tensor, acting: torch.Tensor,
                         demo: torch.Tensor | None = None) -> torch.Tensor:
        """Target y of eq. 4 (:mod:`mope.agent.targets`: one step, or ``n_step`` with each row's Watkins cut, none on
        demonstrations), clamped to the return bounds and, with ``return_mix``, blended with the behaviour's
        greedy-tail returns (and clamped again, with ``seen_bound_margin``)."""
        c = self.config
        nets = (self.q_net, self.target_net, self.buffer, batch.indices, w, acting, c)
        y = targets.n_step_target(*nets, c.n_step, uncut=demo, scale=self.reward_scale) if c.n_step > 1 \
            else targets.one_step_target(*nets, scale=self.reward_scale)
        y = losses.clip_targets(y, self._q_low_t, self._q_high_t) if c.clip_targets or self.bounds_seen else y
        if c.return_mix:
            fresh = self.global_step - self.buffer.return_steps[batch.indices] < c.return_window
            y = losses.mix_behaviour_returns(y, self._tensor(self.buffer.returns[batch.indices]),
                                             self._tensor(fresh, torch.bool), c.return_mix)
            if self.bounds_seen:  # the greedy-tail returns end on the target network's values: clamp the blend too
                y = losses.clip_targets(y, self._q_low_t, self._q_high_t)
        return y

    def _gradient_step(self, loss: torch.Tensor, disc_loss: torch.Tensor | None = None) -> None:
        """One Adam step of the Q-network on ``loss`` (gradient norm clipped) and, given ``disc_loss``, one of the
        discriminator; a single backward pass serves both, since their graphs share no parameter."""
        optimizers = [self.optimizer] + ([self.disc_optimizer] if self.disc_optimizer and disc_loss is not None else [])
        optim.gradient_step(optimizers, loss if disc_loss is None else loss + disc_loss, self._q_params,
                            self.config.max_grad_norm)

    def _set_priorities(self, batch: Batch, priorities: np.ndarray) -> None:
        if not self.buffer.prioritized:
            return
        if not np.all(np.isfinite(priorities)):
            raise TrainingDivergedError(f"training diverged at step {self.global_step}: a replay priority is NaN "
                                        "or inf")
        self.buffer.update_priorities(batch.indices, priorities)

    def _discriminator_loss(self, obs: torch.Tensor, acting_prefs: np.ndarray, feats: torch.Tensor | None = None
                            ) -> tuple[torch.Tensor | None, torch.Tensor | None]:
        """Eq. 6's term ``log q_phi(w|s) - log p(w)`` for the batch and q_phi's cross-entropy loss on ``(s, cell(w_b))``
        (stepped in :meth:`_gradient_step`); ``(None, None)`` without experience exploration."""
        if self.discriminator is None:
            return None, None
        cells_np = self.pref_sampler.partition.cell_of(acting_prefs)
        log_q = self.discriminator.log_prob(obs, self._tensor(cells_np, torch.int64), feats)
        log_p = self._tensor(self.pref_sampler.log_prob_cells(cells_np))
        return losses.mutual_information_bonus(log_q.detach(), log_p), -log_q.mean()


class EQL(MoPE):
    """Envelope Q-learning (Yang et al. 2019): MoPE with experience and preference exploration switched off."""

    variant = "eql"
    strict_variant = True


def agent_class(algo: str) -> type[MoPE]:
    """The class of a variant: :class:`EQL` for ``eql``, :class:`MoPE` for the others."""
    return EQL if check_algo(algo) == "eql" else MoPE


def make_agent(algo: str, env: gym.Env | str, **overrides: Any) -> MoPE:
    """Build the agent of a named variant (``eql``, ``ee``, ``pe``, ``mope``): an :class:`EQL` for ``eql``.
    An env given by id brings its defaults (:data:`mope.config.ENV_DEFAULTS`) for the settings not given."""
    if isinstance(env, str):
        overrides = {"env_id": env, **overrides}
    return agent_class(algo)(env, Config.for_algo(algo, **overrides))
