"""The agents: Envelope Q-learning (EQL) and MoPE = EQL + experience exploration (EE) + preference exploration (PE).

One class, :class:`MoPE`, implements all four variants of the paper's Fig. 2; the two switches
``experience_exploration`` and ``preference_exploration`` select them, and :class:`EQL` is MoPE with both off.

One training step, top to bottom (:meth:`MoPE.train` and :meth:`MoPE.update`):

1. Act epsilon-greedily under the episode's preference ``omega_b`` and store ``(s, omega_b, a, r, s')``.
   At each episode start, ``omega_b`` is drawn uniformly (EQL) or by preference exploration (PE).
2. Sample a batch, with prioritized replay.
3. Give each transition N_omega preferences: uniform ones shared by the batch (EQL, as Yang et al.), or
   ``omega_b`` and its neighbours within sigma_omega (EE).
4. Envelope target y (eq. 4) and the loss L = L^A + L^B (eq. 4); one Adam step.
5. New priorities: the preference-interval TD error (eq. 5), plus, with EE, alpha times the discriminator's
   mutual-information term (eq. 6-7); then one discriminator step.
6. Copy the target network every ``target_update_freq`` steps.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from mope.checkpoint import check_compatible, load_checkpoint, save_checkpoint
from mope.config import Config
from mope.envs import check_env_fits, make_env
from mope.errors import CheckpointError, MopeError
from mope.losses import envelope_target, eql_loss, mutual_information_bonus, preference_interval_td, priority
from mope.networks import Discriminator, QNetwork
from mope.preferences import PreferenceSampler, sample_neighbours, sample_simplex, validate_preference
from mope.replay import ReplayBuffer


class TrainingDivergedError(MopeError):
    """A loss, Q-value or priority became NaN or infinite."""


def resolve_device(name: str) -> torch.device:
    """``cpu``, ``cuda`` or ``auto`` (cuda when available)."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise MopeError("device 'cuda' was asked for but torch sees no CUDA GPU; use --device cpu or auto")
    return torch.device(name)


def linear_schedule(start: float, end: float, duration: int, step: int) -> float:
    """Linear interpolation from ``start`` to ``end`` over ``duration`` steps, then constant."""
    frac = min(1.0, step / max(1, duration))
    return start + frac * (end - start)


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


class MoPE:
    """Multi-objective RL with Preference Exploration (and its ablations, including plain EQL).

    Args:
        env: A Gymnasium/MO-Gymnasium environment, or its id.
        config: A :class:`~mope.config.Config`; default ``Config()`` (the MoPE variant).
        **overrides: Any ``Config`` field, e.g. ``n_omega=64, sigma_omega=0.04, mi_alpha=0.1``.

    Example:
        >>> agent = MoPE("deep-sea-treasure-v0", total_steps=20_000, seed=0)
        >>> agent.train()
        >>> agent.act(obs, [0.3, 0.7])
    """

    #: Switches this class imposes when no config is given.
    default_switches: dict[str, bool] = {"experience_exploration": True, "preference_exploration": True}

    def __init__(self, env: gym.Env | str, config: Config | None = None, **overrides: Any) -> None:
        base = config.to_dict() if config is not None else {**self.default_switches}
        base.pop("algo", None)
        if isinstance(env, str):
            base["env_id"] = env
        elif env.spec is not None:
            base["env_id"] = env.spec.id
        self.config = cfg = Config.from_dict({**base, **overrides})
        self.env = make_env(cfg.env_id, cfg.max_episode_steps) if isinstance(env, str) else env
        spec = check_env_fits(self.env, cfg.env_id)
        self.n_actions, self.m = spec.n_actions, spec.n_objectives
        self.obs_shape = spec.obs_space.shape or ()

        if cfg.torch_threads:
            torch.set_num_threads(cfg.torch_threads)
        self.device = resolve_device(cfg.device)
        self.rng = np.random.default_rng(cfg.seed)
        torch.manual_seed(cfg.seed)

        def q_network() -> QNetwork:
            return QNetwork(spec.obs_space, self.n_actions, self.m, cfg.hidden_sizes, cfg.obs_encoding).to(self.device)

        self.q_net = q_network()
        self.target_net = q_network()
        self.target_net.load_state_dict(self.q_net.state_dict())
        self.target_net.requires_grad_(False)
        self.optimizer = torch.optim.Adam(self.q_net.parameters(), lr=cfg.learning_rate, foreach=True)

        self.pref_sampler = PreferenceSampler(self.m, cfg.n_intervals, cfg.preference_exploration,
                                              cfg.pe_count_offset)
        self.discriminator: Discriminator | None = None
        self.disc_optimizer: torch.optim.Optimizer | None = None
        if cfg.experience_exploration:
            self.discriminator = Discriminator(spec.obs_space, self.pref_sampler.partition.n_cells,
                                               cfg.disc_hidden, cfg.obs_encoding).to(self.device)
            self.disc_optimizer = torch.optim.Adam(self.discriminator.parameters(), lr=cfg.disc_learning_rate,
                                                   foreach=True)

        self.q_low, self.q_high = return_bounds(self.env, cfg.gamma)
        self._q_low_t = torch.as_tensor(self.q_low, dtype=torch.float32, device=self.device)
        self._q_high_t = torch.as_tensor(self.q_high, dtype=torch.float32, device=self.device)
        obs_dtype = np.float32 if not isinstance(spec.obs_space, gym.spaces.Discrete) else np.int64
        self.buffer = ReplayBuffer(cfg.buffer_size, self.obs_shape, self.m, cfg.per, obs_dtype)
        self.global_step = 0
        self.episodes = 0
        #: Training wall seconds before the current ``train`` call (carried across resumes).
        self.wall_s = 0.0
        # The episode in progress (kept across ``train`` calls and in resumable checkpoints): its reset seed,
        # preference, current observation and the actions taken so far (replayed on load to restore the env).
        self._obs: Any = None
        self._pref: np.ndarray | None = None
        self._episode_actions: list[int] = []
        self.last_losses: dict[str, float] = {}
        #: Solutions of the latest evaluation in :meth:`train` (uniform preference set), or None.
        self.last_solutions = None

    # ---------------------------------------------------------------------------------------------------------
    # acting
    # ---------------------------------------------------------------------------------------------------------
    @property
    def algo(self) -> str:
        """``eql``, ``ee``, ``pe`` or ``mope``."""
        return self.config.algo

    @property
    def epsilon(self) -> float:
        """Current exploration rate."""
        c = self.config
        return linear_schedule(c.epsilon_start, c.epsilon_end, c.epsilon_decay_steps, self.global_step)

    def _tensor(self, x: np.ndarray, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x), dtype=dtype, device=self.device)

    @torch.inference_mode()
    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        """Greedy actions ``argmax_a w^T Q(s, a, w)`` for a batch (no input checks; used in rollouts)."""
        obs_t = self._tensor(obs, torch.float32)
        w = self._tensor(prefs)
        q = self.q_net(obs_t, w)
        return torch.einsum("bm,bam->ba", w, q).argmax(dim=1).cpu().numpy()

    def act(self, obs: Any, pref: Any, greedy: bool = True) -> int | np.ndarray:
        """Choose actions under a preference.

        Args:
            obs: One observation, or a batch of them.
            pref: One preference of length m (e.g. ``[0.3, 0.7]``), or one per observation.
            greedy: Greedy if True, else epsilon-greedy with the current epsilon.

        Returns:
            An ``int`` for one observation, an array for a batch.
        """
        obs = np.asarray(obs)
        single = obs.shape == tuple(self.obs_shape)
        obs_b = obs.reshape(1, *self.obs_shape) if single else obs
        prefs = np.atleast_2d(validate_preference(pref, self.m))
        if len(prefs) == 1 and len(obs_b) > 1:
            prefs = np.repeat(prefs, len(obs_b), axis=0)
        if len(prefs) != len(obs_b):
            raise MopeError(f"got {len(obs_b)} observations but {len(prefs)} preferences")
        actions = self.greedy_actions(obs_b, prefs)
        if not greedy:
            explore = self.rng.random(len(actions)) < self.epsilon
            actions = np.where(explore, self.rng.integers(0, self.n_actions, len(actions)), actions)
        return int(actions[0]) if single else actions

    # ---------------------------------------------------------------------------------------------------------
    # learning
    # ---------------------------------------------------------------------------------------------------------
    def relabel(self, acting_prefs: np.ndarray) -> np.ndarray:
        """Preferences of the training rows, ``(B, N_omega, m)``.

        EQL: N_omega uniform preferences shared by the whole batch (Yang et al. 2019). EE (sec. 3, similar
        preference exploration): the transition's own ``omega_b`` plus N_omega - 1 neighbours within sigma_omega.
        """
        c = self.config
        b = len(acting_prefs)
        if not c.experience_exploration:
            shared = sample_simplex(c.n_omega, self.m, self.rng)
            return np.repeat(shared[None], b, axis=0)
        near = sample_neighbours(acting_prefs, c.n_omega - 1, c.sigma_omega, self.rng)
        return np.concatenate([acting_prefs[:, None, :].astype(np.float64), near], axis=1)

    def envelope_set(self, row_prefs: torch.Tensor, acting_prefs: torch.Tensor) -> torch.Tensor:
        """Preferences the envelope max runs over, ``(B, K, m)`` (config ``envelope_prefs``)."""
        mode = self.config.envelope_prefs
        if mode in ("relabel", "own"):
            return row_prefs
        batch = acting_prefs.unsqueeze(0).expand(acting_prefs.shape[0], -1, -1)
        return batch if mode == "batch" else torch.cat([row_prefs, batch], dim=1)

    def update(self) -> dict[str, float]:
        """One gradient step on a sampled batch (steps 2-5 of the module docstring)."""
        c = self.config
        beta = linear_schedule(c.per_beta_start, 1.0, c.total_steps, self.global_step)
        batch = self.buffer.sample(c.batch_size, self.rng, beta)
        obs = self._tensor(batch.obs)
        next_obs = self._tensor(batch.next_obs)
        actions = self._tensor(batch.actions, torch.int64)
        rewards = self._tensor(batch.rewards)
        terminated = self._tensor(batch.terminated)
        is_weights = self._tensor(batch.weights)
        acting = self._tensor(batch.prefs)

        # 3. relabel: every transition gets N_omega preferences
        w = self._tensor(self.relabel(batch.prefs))  # (B, N, m)
        b, n, m = w.shape

        # 4. envelope target (eq. 4), one target-network pass over B x K rows
        with torch.no_grad():
            next_feats = self.target_net.encoder(next_obs)
            y = envelope_target(self.target_net, next_feats, rewards, terminated, w, self.envelope_set(w, acting),
                                c.gamma, select_net=self.q_net if c.double_q else None,
                                envelope=c.envelope_prefs != "own")
            if c.clip_targets:
                y = torch.maximum(torch.minimum(y, self._q_high_t), self._q_low_t)

        feats = self.q_net.encoder(obs)
        feats_rows = feats.unsqueeze(1).expand(b, n, feats.shape[1]).reshape(b * n, -1)
        q_all = self.q_net.forward_features(feats_rows, w.reshape(b * n, m)).view(b, n, self.n_actions, m)
        q = q_all.gather(2, actions.view(b, 1, 1, 1).expand(b, n, 1, m)).squeeze(2)  # (B, N, m)
        loss_rows, l_a, l_b = eql_loss(q, y, w, c.lb_weight)
        loss = (is_weights * loss_rows).mean()
        if not torch.isfinite(loss):
            self._raise_diverged(loss, q, y)

        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if c.max_grad_norm is not None:
            nn.utils.clip_grad_norm_(self.q_net.parameters(), c.max_grad_norm)
        self.optimizer.step()

        # 5. priorities: eq. 5 TD error (+ eq. 6-7 mutual-information term with EE)
        with torch.no_grad():
            td = preference_interval_td(q, y, w)
        stats = {"loss": loss.item(), "loss_a": l_a.mean().item(), "loss_b": l_b.mean().item(),
                 "td_abs": td.abs().mean().item()}
        bonus = None
        if self.discriminator is not None:
            bonus, disc_loss = self._discriminator_step(obs, batch.prefs)
            stats["disc_loss"] = disc_loss
            stats["mi_bonus"] = bonus.mean().item()
        if self.buffer.prioritized:
            pr = priority(td, bonus, c.mi_alpha, c.per_eps).cpu().numpy()
            if not np.all(np.isfinite(pr)):
                raise TrainingDivergedError(
                    f"training diverged at step {self.global_step}: a replay priority is NaN or inf")
            self.buffer.update_priorities(batch.indices, pr**c.per_alpha)
        self.last_losses = stats
        return stats

    def _raise_diverged(self, loss: torch.Tensor, q: torch.Tensor, y: torch.Tensor) -> None:
        """Name the first non-finite quantity of a failed update (checked only once the loss is non-finite)."""
        if not torch.isfinite(q).all():
            what = f"a Q-value is {q[~torch.isfinite(q)][0].item()}"
        elif not torch.isfinite(y).all():
            what = f"an envelope target is {y[~torch.isfinite(y)][0].item()}"
        else:
            what = f"the EQL loss is {loss.item()}"
        raise TrainingDivergedError(f"training diverged at step {self.global_step}: {what}")

    def _discriminator_step(self, obs: torch.Tensor, acting_prefs: np.ndarray) -> tuple[torch.Tensor, float]:
        """Mutual-information term (eq. 6) for the batch, then one cross-entropy step of q_phi on (s, cell(w_b))."""
        assert self.discriminator is not None and self.disc_optimizer is not None
        cells_np = self.pref_sampler.partition.cell_of(acting_prefs)
        cells = self._tensor(cells_np, torch.int64)
        logits = self.discriminator(obs)
        log_q = torch.log_softmax(logits, dim=1).gather(1, cells.view(-1, 1)).squeeze(1)
        log_p = self._tensor(self.pref_sampler.log_prob_cells(cells_np))
        bonus = mutual_information_bonus(log_q.detach(), log_p)
        disc_loss = -log_q.mean()
        self.disc_optimizer.zero_grad(set_to_none=True)
        disc_loss.backward()
        self.disc_optimizer.step()
        return bonus, disc_loss.item()

    def train(self, total_timesteps: int | None = None, eval_env: gym.Env | None = None,
              eval_every: int | None = None, callback: Callable[[MoPE, dict[str, float]], None] | None = None,
              progress: bool = False, stop: Callable[[], bool] | None = None,
              on_step: Callable[[MoPE], None] | None = None) -> list[dict[str, float]]:
        """Train for ``total_timesteps`` environment steps (default ``config.total_steps``).

        Args:
            total_timesteps: Steps to run now (training continues from ``global_step``).
            eval_env: If given, evaluate with the paper's protocol every ``eval_every`` steps and at the end.
            eval_every: Default ``config.eval_every``.
            callback: Called with ``(agent, record)`` after each evaluation.
            progress: Show a progress bar with the latest CR.
            stop: Polled once per step; when it returns True, training stops at that step boundary (no final
                evaluation). ``train_run`` uses it to turn SIGINT/SIGTERM into a clean stop.
            on_step: Called with the agent at the end of every step (after any evaluation); ``train_run`` writes
                its periodic checkpoints from it.

        The episode in progress carries over from one call to the next, so ``train(500)`` twice equals
        ``train(1000)`` (evaluations aside).

        Returns:
            The evaluation records (step, wall seconds and every metric of :class:`~mope.evaluation.Evaluator`).
        """
        from tqdm.auto import tqdm

        from mope.evaluation import Evaluator

        c = self.config
        total = c.total_steps if total_timesteps is None else int(total_timesteps)
        if total < 1:
            raise MopeError(f"total_timesteps={total} is out of range: must be >= 1")
        every = c.eval_every if eval_every is None else eval_every
        evaluator = (Evaluator(eval_env, c.env_id, c.gamma, c.eval_prefs, c.seed, c.max_episode_steps, c.ref_point)
                     if eval_env is not None else None)
        records: list[dict[str, float]] = []
        t0 = time.perf_counter()

        def evaluate() -> None:
            assert evaluator is not None
            res, self.last_solutions = evaluator.evaluate(self)
            rec = {"step": self.global_step, "wall_s": self.wall_s + time.perf_counter() - t0, **res}
            records.append(rec)
            bar.set_postfix(cr=f"{res['cr']:.3f}", eum=f"{res['eum']:.2f}", refresh=False)
            if callback is not None:
                callback(self, rec)

        if self._obs is None:
            self._start_episode()
        end = self.global_step + total
        with tqdm(total=total, disable=not progress, desc=f"{c.algo} {c.env_id}", unit="step",
                  dynamic_ncols=True, mininterval=0.5) as bar:
            while self.global_step < end:
                if stop is not None and stop():
                    self.wall_s += time.perf_counter() - t0
                    return records
                # 1. act epsilon-greedily under the episode's preference and store the transition
                obs, pref = self._obs, self._pref
                assert pref is not None
                if self.rng.random() < self.epsilon:
                    action = int(self.rng.integers(self.n_actions))
                else:
                    action = int(self.greedy_actions(np.asarray(obs)[None], pref[None])[0])
                next_obs, reward, terminated, truncated, _ = self.env.step(action)
                self.buffer.add(obs, pref, action, np.asarray(reward, dtype=np.float32), next_obs, terminated)
                self._obs = next_obs
                self._episode_actions.append(action)
                self.global_step += 1
                if terminated or truncated:
                    self.episodes += 1
                    self._start_episode()

                # 2-5. learn
                if self.global_step > c.learning_starts and len(self.buffer) >= c.batch_size:
                    for _ in range(c.gradient_steps):
                        self.update()
                # 6. target network
                if self.global_step % c.target_update_freq == 0:
                    self.target_net.load_state_dict(self.q_net.state_dict())

                bar.update(1)
                if evaluator is not None and every and self.global_step % every == 0:
                    evaluate()
                if on_step is not None:
                    on_step(self)
            if evaluator is not None and (not records or records[-1]["step"] != self.global_step):
                evaluate()
        self.wall_s += time.perf_counter() - t0
        return records

    def _start_episode(self) -> None:
        """Reset the training env (seeded by the episode count) and draw the episode's preference."""
        self._obs, _ = self.env.reset(seed=self.config.seed + self.episodes)
        self._pref = self.pref_sampler.sample(self.rng)
        self._episode_actions = []

    def _restore_episode(self, pref: np.ndarray, actions: list[int]) -> None:
        """Rebuild the episode in progress by replaying its actions from its seeded reset (no RNG draws)."""
        self._obs, _ = self.env.reset(seed=self.config.seed + self.episodes)
        for a in actions:
            self._obs, *_ = self.env.step(int(a))
        self._pref = np.asarray(pref, dtype=np.float64)
        self._episode_actions = [int(a) for a in actions]

    # ---------------------------------------------------------------------------------------------------------
    # saving and loading
    # ---------------------------------------------------------------------------------------------------------
    def state_dict(self, include_buffer: bool = False) -> dict[str, Any]:
        """Everything needed to act (and, with ``include_buffer``, to resume training)."""
        state: dict[str, Any] = {
            "config": self.config.to_dict(),
            "env": {"n_actions": self.n_actions, "n_objectives": self.m, "obs_shape": list(self.obs_shape)},
            "q_net": self.q_net.state_dict(),
            "target_net": self.target_net.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "preference_sampler": self.pref_sampler.state_dict(),
            "global_step": self.global_step,
            "episodes": self.episodes,
            "rng": self.rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "wall_s": self.wall_s,
        }
        if self.discriminator is not None and self.disc_optimizer is not None:
            state["discriminator"] = self.discriminator.state_dict()
            state["disc_optimizer"] = self.disc_optimizer.state_dict()
        if include_buffer:
            state["buffer"] = {k: torch.as_tensor(v) if isinstance(v, np.ndarray) else v
                               for k, v in self.buffer.state_dict().items()}
            if self._pref is not None:
                state["episode"] = {"pref": torch.as_tensor(self._pref),
                                    "actions": torch.as_tensor(self._episode_actions, dtype=torch.int64)}
            state["last_losses"] = dict(self.last_losses)
        return state

    def save(self, path: str | Path, include_buffer: bool = False) -> Path:
        """Write a checkpoint (atomically). ``MoPE.load`` / ``EQL.load`` read it back."""
        return save_checkpoint(path, self.state_dict(include_buffer))

    @classmethod
    def load(cls, path: str | Path, env: gym.Env | None = None, **overrides: Any) -> MoPE:
        """Load a checkpoint written by :meth:`save`.

        The saved config decides the variant; ``env`` defaults to a new instance of the saved environment.

        Raises:
            CheckpointError: for a missing, corrupt, unsafe or incompatible checkpoint.
        """
        data = load_checkpoint(path)
        try:
            config = Config.from_dict(data["config"])
        except MopeError as exc:
            raise CheckpointError(f"checkpoint '{path}' holds an invalid config: {exc}") from None
        if overrides:
            config = Config.from_dict({**config.to_dict(), **overrides})  # a bad override is the caller's error
        agent = MoPE(env if env is not None else config.env_id, config)
        check_compatible(data, path, agent.config.env_id, agent.m, agent.n_actions, tuple(agent.obs_shape),
                         same_env="env_id" not in overrides)
        try:
            agent.load_state_dict(data)
        except (RuntimeError, KeyError) as exc:
            first = str(exc).splitlines()[0]
            raise CheckpointError(f"checkpoint '{path}' does not fit its config: {first}") from None
        return agent

    def load_state_dict(self, data: dict[str, Any]) -> None:
        """Restore networks, optimizers, counts, step counters, RNG states and (if present) the replay buffer."""
        self.q_net.load_state_dict(data["q_net"])
        self.target_net.load_state_dict(data["target_net"])
        self.optimizer.load_state_dict(data["optimizer"])
        if self.discriminator is not None and "discriminator" in data:
            self.discriminator.load_state_dict(data["discriminator"])
            self.disc_optimizer.load_state_dict(data["disc_optimizer"])  # type: ignore[union-attr]
        self.pref_sampler.load_state_dict(data["preference_sampler"])
        self.global_step = int(data["global_step"])
        self.episodes = int(data["episodes"])
        self.rng.bit_generator.state = data["rng"]
        torch.set_rng_state(data["torch_rng"])
        self.wall_s = float(data.get("wall_s", 0.0))
        if "buffer" in data:
            self.buffer.load_state_dict({k: v.numpy() if isinstance(v, torch.Tensor) else v
                                         for k, v in data["buffer"].items()})
            self.last_losses = dict(data.get("last_losses", {}))
        if "episode" in data:
            self._restore_episode(data["episode"]["pref"].numpy(), data["episode"]["actions"].tolist())

    def __repr__(self) -> str:
        return f"{type(self).__name__}(env={self.config.env_id!r}, algo={self.algo!r}, step={self.global_step})"


class EQL(MoPE):
    """Envelope Q-learning (Yang et al. 2019): MoPE with experience and preference exploration switched off."""

    default_switches = {"experience_exploration": False, "preference_exploration": False}


def make_agent(algo: str, env: gym.Env | str, **overrides: Any) -> MoPE:
    """Build the agent of a named variant (``eql``, ``ee``, ``pe``, ``mope``)."""
    return MoPE(env, Config.for_algo(algo, **overrides))


