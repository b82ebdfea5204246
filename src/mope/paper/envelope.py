"""Peers behind mope's interfaces: morl-baselines' Envelope, trained and evaluated exactly as mope's agents are.

morl-baselines is never a runtime dependency: it comes with the optional ``bench`` extra, installed in a separate
environment (``pip install -e ".[bench]"``); everything here imports it lazily and says so when it is missing.
``benchmarks/bench_envelope.py`` and ``mope benchmark`` use these classes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mope.errors import MopeError

#: morl-baselines' Envelope example (examples/envelope_minecart.py) with gamma 0.99 and epsilon decayed over 10k
#: steps: mope's ``envelope`` preset mirrors these settings.
ENVELOPE_EXAMPLE: dict[str, Any] = {"learning_rate": 3e-4, "batch_size": 64, "net_arch": [256, 256, 256, 256],
                                    "initial_epsilon": 1.0, "final_epsilon": 0.05, "epsilon_decay_steps": 10_000,
                                    "initial_homotopy_lambda": 0.0, "final_homotopy_lambda": 1.0,
                                    "homotopy_decay_steps": 10_000, "learning_starts": 100,
                                    "target_net_update_freq": 1000, "tau": 1.0, "max_grad_norm": 0.1,
                                    "buffer_size": 2_000_000, "num_sample_w": 4, "per": True, "per_alpha": 0.6}
MISSING = ("morl-baselines is not installed: it comes with the optional bench extra, in a separate environment: "
           "python3 -m venv .venv-bench && .venv-bench/bin/pip install torch==2.13.0 -e '.[bench]'")


def require_morl_baselines() -> None:
    """Raise a one-line :class:`MopeError` when morl-baselines is missing."""
    try:
        import morl_baselines  # noqa: F401
    except ImportError:
        raise MopeError(MISSING) from None


class EnvelopePolicy:
    """mope's ``GreedyPolicy`` (and ``q_values``) over an Envelope agent: one batched Q-network pass per call."""

    def __init__(self, agent: Any) -> None:
        self.agent = agent

    def q_values(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        """Vector Q-values ``(n, A, m)``: the input Envelope's own ``max_action`` gives its network."""
        import torch

        with torch.no_grad():
            o = torch.as_tensor(np.asarray(obs), dtype=torch.float32).reshape(len(obs), -1)
            return self.agent.q_net(o, torch.as_tensor(np.asarray(prefs), dtype=torch.float32)).numpy()

    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        return np.einsum("nam,nm->na", self.q_values(obs, prefs), np.asarray(prefs)).argmax(axis=1)


class EnvelopeRunner:
    """morl-baselines' Envelope, trained in chunks that continue one another exactly.

    Its training loop (:meth:`train`) is a step-for-step copy of ``Envelope.train``'s loop (morl-baselines 1.3.0)
    without the logging and evaluation branches, keeping the observation, the episode's weight, ``global_step``
    (hence the epsilon schedule) and the replay buffer across chunks; ``Envelope.train`` itself would reset the
    environment and draw a new weight at each call. The only addition is seeding the first reset and the action
    space, which morl-baselines leaves unseeded.

    Args:
        env_id: The environment.
        seed: Seed of everything (``seed_everything``, the env's first reset, the action space).
        gamma: Discount.
        overrides: Envelope constructor arguments (on top of ``gamma``, ``seed``, ``log=False``, cpu).
        max_episode_steps: Time limit, ``None`` for the registered one.
    """

    def __init__(self, env_id: str, seed: int, gamma: float = 0.99, overrides: dict[str, Any] | None = None,
                 max_episode_steps: int | None = None) -> None:
        require_morl_baselines()
        import mo_gymnasium as mo_gym
        from mo_gymnasium.wrappers import MORecordEpisodeStatistics
        from morl_baselines.common.evaluation import seed_everything
        from morl_baselines.common.weights import random_weights
        from morl_baselines.multi_policy.envelope.envelope import Envelope

        import mope.envs  # noqa: F401 - registers mope's environments

        seed_everything(seed)
        kwargs_env = {"max_episode_steps": max_episode_steps} if max_episode_steps else {}
        env = MORecordEpisodeStatistics(mo_gym.make(env_id, **kwargs_env), gamma=gamma)
        env.action_space.seed(seed)
        kwargs: dict[str, Any] = {"gamma": gamma, "log": False, "seed": seed, "device": "cpu", **(overrides or {})}
        self.agent = Envelope(env, **kwargs)
        self._random_weights = random_weights
        self.env = env
        self.agent.global_step = 0
        self.agent.num_episodes = 0
        self.obs, _ = env.reset(seed=seed)
        self._new_weight()

    def _new_weight(self) -> None:
        import torch

        a = self.agent
        self.w = self._random_weights(a.reward_dim, 1, dist="gaussian", rng=a.np_random)
        self.tensor_w = torch.tensor(self.w).float().to(a.device)

    @property
    def global_step(self) -> int:
        return int(self.agent.global_step)

    def train(self, steps: int) -> None:
        """``steps`` iterations of ``Envelope.train``'s loop body, logging left out."""
        import torch

        a, env = self.agent, self.env
        for _ in range(steps):
            if a.global_step < a.learning_starts:
                action = env.action_space.sample()
            else:
                action = a.act(torch.as_tensor(self.obs).float().to(a.device), self.tensor_w)
            next_obs, vec_reward, terminated, truncated, _ = env.step(action)
            a.global_step += 1
            a.replay_buffer.add(self.obs, action, vec_reward, next_obs, terminated)
            if a.global_step >= a.learning_starts:
                a.update()
            if terminated or truncated:
                self.obs, _ = env.reset()
                a.num_episodes += 1
                self._new_weight()
            else:
                self.obs = next_obs

    def policy(self) -> EnvelopePolicy:
        return EnvelopePolicy(self.agent)

    @property
    def learning_starts(self) -> int:
        return int(self.agent.learning_starts)

    @property
    def q_net(self) -> Any:
        return self.agent.q_net


__all__ = ["ENVELOPE_EXAMPLE", "EnvelopePolicy", "EnvelopeRunner", "require_morl_baselines"]
