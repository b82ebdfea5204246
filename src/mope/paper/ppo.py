"""The outer-loop baseline of the paper's Fig. 5: one single-objective PPO policy per preference.

For each of K preferences ``w`` (default 11, equally spaced), Stable-Baselines3's PPO is trained on the
scalarised reward ``w^T r`` of the continuous Robot Confrontation Game, through MO-Gymnasium's
``LinearReward`` wrapper. Each policy is then played (deterministically) for several episodes; the vector
returns, discounted and undiscounted, and the episode outcomes are kept.

:func:`play_episodes` plays many episodes of any batched policy at once (one policy call per time step for
all running episodes); ``mope reproduce confrontation`` uses it for PPO, EQL and MoPE alike.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from mope.errors import ConfigError
from mope.preferences import equally_spaced, validate_preference

#: PPO settings (SB3 defaults except n_steps, so that a 20k-step budget gives ~20 policy updates).
PPO_DEFAULTS: dict[str, Any] = {"n_steps": 1024, "batch_size": 64, "n_epochs": 10, "learning_rate": 3e-4,
                                "gamma": 0.99, "gae_lambda": 0.95, "ent_coef": 0.0}


@dataclass
class Episodes:
    """Results of ``n`` episodes (one row each)."""

    returns: np.ndarray  #: ``(n, m)`` undiscounted vector returns
    discounted: np.ndarray  #: ``(n, m)`` discounted vector returns
    lengths: np.ndarray  #: ``(n,)``
    outcomes: list[str]  #: ``info["outcome"]`` of the last step ("running" when the time limit ended it)
    histories: list[np.ndarray] = field(default_factory=list)  #: ``(T + 1, 2, 4)`` states, if recorded


def play_episodes(policy: Callable[[np.ndarray, np.ndarray], np.ndarray], make: Callable[[], gym.Env],
                  n: int, seeds: Sequence[int], max_steps: int, gamma: float = 0.99,
                  record: bool = False) -> Episodes:
    """Play ``n`` episodes side by side; ``policy(obs_batch, episode_idx) -> actions`` is called once per step.

    Args:
        policy: Maps the ``(k, obs_dim)`` observations of the running episodes and their indices to ``k`` actions.
        make: Builds one environment (unwrapped or wrapped; its time limit is not relied upon).
        n: Number of episodes.
        seeds: Reset seed of each episode (length ``n``).
        max_steps: Episode length limit.
        gamma: Discount of ``discounted``.
        record: Keep every episode's state history (``env.unwrapped.history``).
    """
    if len(seeds) != n:
        raise ConfigError(f"got {len(seeds)} seeds for {n} episodes")
    from mope.envs.confrontation_batch import ConfrontationBatch

    probe = make()
    if ConfrontationBatch.supports(probe):  # the game, stepped as arrays: the same episodes, far faster
        return _play_batched(policy, ConfrontationBatch(probe, n, seeds=list(seeds), record=record), max_steps,
                             gamma)
    envs = [probe] + [make() for _ in range(n - 1)]
    obs = np.stack([e.reset(seed=int(s))[0] for e, s in zip(envs, seeds, strict=True)])
    m = int(envs[0].unwrapped.reward_space.shape[0])
    ret, disc = np.zeros((n, m)), np.zeros((n, m))
    lengths = np.zeros(n, dtype=np.int64)
    outcomes = ["running"] * n
    running = np.arange(n)
    g = 1.0
    for _ in range(max_steps):
        actions = policy(obs[running], running)
        done = np.zeros(len(running), dtype=bool)
        for j, (i, a) in enumerate(zip(running, actions, strict=True)):
            o, r, term, trunc, info = envs[i].step(a)
            obs[i] = o
            ret[i] += r
            disc[i] += g * np.asarray(r, dtype=np.float64)
            lengths[i] += 1
            outcomes[i] = info.get("outcome", "running")
            done[j] = term or trunc
        running = running[~done]
        g *= gamma
        if running.size == 0:
            break
    histories = [np.asarray(e.unwrapped.history) for e in envs] if record else []
    for e in envs:
        e.close()
    return Episodes(ret, disc, lengths, outcomes, histories)


def _play_batched(policy: Callable[[np.ndarray, np.ndarray], np.ndarray], batch: Any, max_steps: int,
                  gamma: float) -> Episodes:
    """:func:`play_episodes` on a batched game (:class:`mope.envs.confrontation_batch.ConfrontationBatch`)."""
    n = batch.n
    obs = batch.reset()
    ret, disc = np.zeros((n, 2)), np.zeros((n, 2))
    lengths = np.zeros(n, dtype=np.int64)
    running = np.arange(n)
    g = 1.0
    for _ in range(max_steps):
        o, r, term = batch.step(running, np.asarray(policy(obs[running], running)))
        obs[running] = o
        ret[running] += r
        disc[running] += g * r
        lengths[running] += 1
        running = running[~term]
        g *= gamma
        if running.size == 0:
            break
    return Episodes(ret, disc, lengths, batch.outcomes(), batch.histories() if batch.record else [])


@dataclass
class PPOResult:
    """One PPO policy of the baseline and its evaluation."""

    pref: np.ndarray
    model: Any
    episodes: Episodes | None = None


def make_scalarized_env(env_id: str, pref: np.ndarray, **env_kwargs: Any) -> gym.Env:
    """The single-objective task of one preference: ``LinearReward(mo_gymnasium.make(env_id), pref)``, with a
    continuous action box rescaled to [-1, 1] (``RescaleAction``): SB3's Gaussian policy starts with standard
    deviation 1, so on the raw box ([-0.2, 0.2] x [-0.8, 0.8] for the confrontation game) most early actions would
    be clipped to its bounds."""
    import mo_gymnasium as mo_gym
    from gymnasium.wrappers import RescaleAction, TransformReward
    from mo_gymnasium.wrappers import LinearReward

    import mope.envs.confrontation  # noqa: F401 - registers the confrontation ids

    env = mo_gym.make(env_id, **env_kwargs)
    if isinstance(env.action_space, gym.spaces.Box):
        env = RescaleAction(env, -1.0, 1.0)
    return TransformReward(LinearReward(env, weight=np.asarray(pref, dtype=np.float32)), float)


def rescale_to_box(action: np.ndarray, space: gym.spaces.Box) -> np.ndarray:
    """Map actions in [-1, 1] (what a policy trained through ``RescaleAction`` outputs) back onto ``space``."""
    x = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
    return space.low + (x + 1.0) * 0.5 * (space.high - space.low)


def train_ppo(pref: Any, steps: int, seed: int = 0, env_id: str = "mope/RobotConfrontation-v0",
              device: str = "cpu", ppo_kwargs: dict[str, Any] | None = None, **env_kwargs: Any) -> Any:
    """Train one SB3 PPO policy on the scalarised reward ``pref^T r`` of ``env_id`` (seeded, CPU by default).

    Returns:
        The trained ``stable_baselines3.PPO`` model.
    """
    from stable_baselines3 import PPO

    if steps < 1:
        raise ConfigError(f"PPO steps={steps} is out of range: must be >= 1")
    w = validate_preference(pref, 2)
    env = make_scalarized_env(env_id, w, **env_kwargs)
    kwargs = {**PPO_DEFAULTS, **(ppo_kwargs or {})}
    # a short budget still gets a full rollout; rollouts are whole mini-batches (no truncated last batch)
    batch = int(kwargs["batch_size"])
    kwargs["n_steps"] = max(batch, min(int(kwargs["n_steps"]), steps) // batch * batch)
    model = PPO("MlpPolicy", env, seed=seed, device=device, verbose=0, **kwargs)
    model.learn(total_timesteps=steps)
    return model


def ppo_policy(model: Any, space: gym.spaces.Box | None = None) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """A batched deterministic policy for :func:`play_episodes`; with ``space``, the model's [-1, 1] actions (it
    was trained through ``RescaleAction``) are mapped back onto that box."""

    def act(obs: np.ndarray, _idx: np.ndarray) -> np.ndarray:
        a = model.predict(obs, deterministic=True)[0]
        return rescale_to_box(a, space) if space is not None else a

    return act


def ppo_baseline(steps: int, n_prefs: int = 11, seed: int = 0, episodes: int = 5, eval_seed: int = 10_000,
                 env_id: str = "mope/RobotConfrontation-v0", device: str = "cpu", gamma: float = 0.99,
                 max_steps: int | None = None, ppo_kwargs: dict[str, Any] | None = None,
                 prefs: np.ndarray | None = None) -> list[PPOResult]:
    """Train one PPO policy per preference and play each for ``episodes`` episodes.

    Args:
        steps: Environment steps per policy.
        n_prefs: K, the number of equally spaced preferences (ignored when ``prefs`` is given).
        seed: Training seed of policy ``k`` is ``seed + k``.
        episodes: Evaluation episodes per policy, reset seeds ``eval_seed + j``.
        max_steps: Evaluation episode length (default the registered time limit).
    """
    import mo_gymnasium as mo_gym

    if n_prefs < 1 or episodes < 1:
        raise ConfigError(f"n_prefs={n_prefs} and episodes={episodes} must be >= 1")
    ws = equally_spaced(2, n_prefs) if prefs is None else np.atleast_2d(np.asarray(prefs, dtype=np.float64))
    out = []
    for k, w in enumerate(ws):
        model = train_ppo(w, steps, seed + k, env_id, device, ppo_kwargs)
        out.append(PPOResult(np.asarray(w), model))
    limit = max_steps or gym.spec(env_id).max_episode_steps or 1000
    for res in out:
        space = mo_gym.make(env_id).action_space
        res.episodes = play_episodes(ppo_policy(res.model, space), lambda: mo_gym.make(env_id).unwrapped, episodes,
                                     [eval_seed + j for j in range(episodes)], limit, gamma)
    return out
