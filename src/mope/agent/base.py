"""Acting and collecting experience: the half of an agent that does not learn (Stable-Baselines3's policy side).

:class:`BaseAgent` is the base class of :class:`mope.agent.agent.MoPE`. It acts (greedy or epsilon-greedy, batched),
steps the training environment and stores transitions (:meth:`BaseAgent.collect_step`), and hands the training
loop to :mod:`mope.agent.runner`. The subclass builds the networks, the replay buffer and the preference sampler, and
learns.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch

from mope.agent import losses
from mope.agent.agent_state import AgentState, Episode
from mope.agent.demonstrations import label_actions
from mope.agent.replay import ReplayBuffer
from mope.config import epsilon_decay_steps_of
from mope.errors import MopeError
from mope.preferences import validate_preference


def suffix_returns(rewards: np.ndarray, gamma: float) -> np.ndarray:
    """``(T, m)`` rewards of one episode -> ``(T, m)`` discounted returns from each step to its end (a backward
    recursion ``G_t = r_t + gamma G_{t+1}``, as a linear filter)."""
    from scipy.signal import lfilter

    r = np.asarray(rewards, dtype=np.float64)
    return lfilter([1.0], [1.0, -gamma], r[::-1], axis=0)[::-1]


def seen_upper_bound(space_high: np.ndarray, seen_low: np.ndarray, seen_high: np.ndarray, margin: float
                     ) -> np.ndarray:
    """The targets' upper clamp per objective: the reward space's bound, or the largest return seen plus
    ``margin`` times the range seen, whichever is lower (not in the paper).

    A target above every return any episode reached from any state is the max operator's upward drift feeding on
    itself (minecart's Q-values climb to 161 where a trip brings 1.5); the margin leaves room for continuations
    that join the best pieces of several episodes.
    """
    return np.minimum(space_high, seen_high + margin * (seen_high - seen_low))


#: The longest run of one random action under ``epsilon_repeat_mu`` (Deep-Sea-Treasure's time limit).
MAX_REPEAT = 100


def repeat_exploration(episodes: list[Episode], actions: np.ndarray, explored: np.ndarray, mu: float,
                       rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """ez-greedy (Dabney, Ostrovski and Barreto 2021) over epsilon-greedy ``actions``: an env still inside an
    exploration takes its previous, random, action again; one that starts exploring now (``explored``, not going on)
    keeps its random action for n ~ zeta(mu) steps in all (at most :data:`MAX_REPEAT`; the episode's end stops it, and
    so does a step that does not move: :func:`end_stalled_repeats`). Straight runs reach far cells a one-step random
    walk rarely does (the mirrored map's 124 treasure; docs/results/ez-greedy).

    Returns:
        The actions and which rows took a random one; each episode's ``repeat`` is advanced in place.
    """
    going = np.array([ep.repeat > 0 for ep in episodes])
    starting = explored & ~going
    actions = actions.copy()
    for i in np.flatnonzero(going):
        actions[i] = episodes[i].actions[-1]
        episodes[i].repeat -= 1
    for i, n in zip(np.flatnonzero(starting), np.minimum(rng.zipf(mu, int(starting.sum())), MAX_REPEAT), strict=True):
        episodes[i].repeat = int(n) - 1
    return actions, explored | going


def end_stalled_repeats(episodes: list[Episode], obs: np.ndarray, next_obs: np.ndarray) -> None:
    """End the repeated random action of every env whose observation it did not change (a run into a wall): kept,
    it would fill the buffer with self-loops (60 % of random play's transitions on the grid worlds, against 14-23 %
    with one-step actions), whose bootstrapped targets feed on their own values."""
    for i, ep in enumerate(episodes):
        if ep.repeat and np.array_equal(obs[i], next_obs[i]):
            ep.repeat = 0


def linear_schedule(start: float, end: float, duration: int, step: int) -> float:
    """Linear interpolation from ``start`` to ``end`` over ``duration`` steps, then constant."""
    frac = min(1.0, step / max(1, duration))
    return start + frac * (end - start)


class BaseAgent(AgentState):
    """Acting, collection and the training entry point of a preference-conditioned Q agent."""

    q_net: torch.nn.Module
    envs: list[gym.Env]
    episodes: int
    episodes_started: int
    _episodes: list[Episode] | None
    target_net: torch.nn.Module
    buffer: ReplayBuffer
    n_actions: int
    m: int
    obs_shape: tuple[int, ...]
    device: torch.device
    rng: np.random.Generator
    global_step: int
    q_low: np.ndarray
    q_high: np.ndarray
    #: Every reward's factor in the learner (``reward_scale``, with ``reward_norm``: :func:`learner_reward_scale`).
    reward_scale: float
    #: ``(2, m)``: the lowest and highest discounted return seen from any state of an ended episode (with
    #: ``seen_bound_margin``; None before the first).
    seen_returns: np.ndarray | None = None
    #: ``(length, terminated, undiscounted return)`` of the training episodes ended since the last
    #: :meth:`pop_episode_stats` (the training-episode columns of ``train_stats.csv``).
    ended_episodes: list[tuple[int, bool, np.ndarray]]
    #: Which rows of the latest epsilon-greedy :meth:`act` took a random action.
    _explored: np.ndarray | None = None
    #: The greedy action of each row of the latest :meth:`act` (-1 where it was not computed).
    _greedy: np.ndarray | None = None

    @property
    def algo(self) -> str:
        """``eql``, ``ee``, ``pe`` or ``mope``."""
        return self.config.algo

    @property
    def epsilon(self) -> float:
        """Current exploration rate."""
        c = self.config
        return linear_schedule(c.epsilon_start, c.epsilon_end, epsilon_decay_steps_of(c), self.global_step)

    def _tensor(self, x: np.ndarray, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x), dtype=dtype, device=self.device)

    @torch.inference_mode()
    def q_values(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        """Vector Q-values ``(n, |A|, m)`` for a batch, in the environment's units (no input checks; used by
        diagnostics)."""
        q = self.q_net(self._tensor(obs), self._tensor(prefs)).cpu().numpy()
        return q if self.reward_scale == 1.0 else q / self.reward_scale

    @torch.inference_mode()
    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray:
        """Greedy actions ``argmax_a w^T Q(s, a, w)`` for a batch (no input checks; used in rollouts)."""
        return self.q_net.greedy(self._tensor(obs), self._tensor(prefs)).cpu().numpy()

    def act(self, obs: Any, pref: Any, greedy: bool = True) -> int | np.ndarray:
        """Choose actions under a preference.

        Args:
            obs: One observation, or a batch of them.
            pref: One preference of length m (e.g. ``[0.3, 0.7]``), or one per observation.
            greedy: Greedy if True, else epsilon-greedy with the current epsilon: each observation explores with
                probability epsilon (one uniform draw each), and an exploring one takes a uniform random action.

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
        actions = np.zeros(len(obs_b), dtype=np.int64)
        explore = np.zeros(len(obs_b), dtype=bool)
        if not greedy:
            explore = self.rng.random(len(obs_b)) < self.epsilon
            actions[explore] = self.rng.integers(0, self.n_actions, int(explore.sum()))
        # With return_mix, collection also needs the explored rows' greedy actions: one pass over every row.
        need = np.ones(len(obs_b), dtype=bool) if not greedy and self.config.return_mix else ~explore
        best = np.full(len(obs_b), -1, dtype=np.int64)
        if need.any():
            best[need] = self.greedy_actions(obs_b[need], prefs[need])
            actions[~explore] = best[~explore]
        self._explored = explore  # which rows took a random action (collect_step's greedy-tail trace reads it)
        self._greedy = best  # the greedy action of each row (-1: not computed)
        return int(actions[0]) if single else actions

    # ---------------------------------------------------------------------------------------------------------
    # collection
    # ---------------------------------------------------------------------------------------------------------
    def collect_step(self) -> None:
        """Step 1: one epsilon-greedy step of each of the ``n_envs`` training envs under its episode's
        preference (one forward pass acts for all of them), the ``n_envs`` transitions stored in the buffer."""
        if self._episodes is None:
            self._episodes = [self._start_episode(i) for i in range(len(self.envs))]
        eps = self._episodes
        obs = np.stack([np.asarray(ep.obs) for ep in eps])
        prefs = np.stack([ep.pref for ep in eps])
        self._explored = self._greedy = None
        actions = np.asarray(self.act(obs, prefs, greedy=False))
        if self.config.epsilon_repeat_mu is not None:
            actions, self._explored = repeat_exploration(eps, actions, self._explored, self.config.epsilon_repeat_mu,
                                                         self.rng)
        expert = self._expert_labels(obs, prefs)
        steps = [env.step(int(a)) for env, a in zip(self.envs, actions, strict=True)]
        next_obs = np.stack([np.asarray(s[0]) for s in steps])
        end_stalled_repeats(eps, obs, next_obs)  # ez-greedy's runs into a wall end (no repeats: nothing to do)
        rewards = np.stack([np.asarray(s[1], dtype=np.float32) for s in steps])
        terminated = np.array([bool(s[2]) for s in steps])
        done = terminated | np.array([bool(s[3]) for s in steps])
        slots = self.buffer.add_batch(obs, prefs, actions, rewards, next_obs, terminated, done, expert)
        if self.config.return_mix:  # the trace of each episode's greedy tail (mope.agent.losses.greedy_tail_returns)
            greedy = self._greedy_trace(obs, prefs, actions)
        self.global_step += len(eps)
        for i, ep in enumerate(eps):
            ep.obs = next_obs[i] if len(eps) > 1 else steps[i][0]
            ep.actions.append(int(actions[i]))
            ep.rewards.append(rewards[i])
            if self.config.return_mix:
                ep.slots.append(int(slots[i]))
                ep.greedy.append(bool(greedy[i]))
            if done[i]:
                ep_rewards = np.stack(ep.rewards)
                if self.bounds_seen:
                    self.observe_returns(ep_rewards)
                self.ended_episodes.append((len(ep_rewards), bool(terminated[i]), ep_rewards.sum(axis=0)))
                if self.config.return_mix:
                    self.store_episode_returns(ep, bool(terminated[i]))
                self.episodes += 1
                eps[i] = self._start_episode(i)

    def pop_episode_stats(self) -> dict[str, float]:
        """Statistics of the training episodes ended since the last call, then forgotten: ``episodes`` (how many),
        ``ep_len`` (mean length), ``ep_end_share`` (the share that ended in a terminal state, not at the time limit)
        and ``ep_return_<i>`` (mean undiscounted return of objective ``i``, in the environment's units), as SB3's
        ``rollout/ep_rew_mean``; empty when none ended."""
        ended, self.ended_episodes = self.ended_episodes, []
        if not ended:
            return {}
        returns = np.mean([r for _, _, r in ended], axis=0)
        return {"episodes": float(len(ended)), "ep_len": float(np.mean([n for n, _, _ in ended])),
                "ep_end_share": float(np.mean([t for _, t, _ in ended])),
                **{f"ep_return_{i}": float(v) for i, v in enumerate(returns)}}

    @property
    def bounds_seen(self) -> bool:
        """Whether the targets' upper clamp follows the returns seen (``seen_bound_margin``)."""
        return self.config.seen_bound_margin is not None

    def observe_demonstrations(self, demos: Any) -> None:
        """Fold every demonstrated episode into the returns seen (:meth:`observe_returns`), with
        ``seen_bound_margin``; ``demos``: :class:`~mope.agent.demonstrations.Demonstrations` or None."""
        if demos is not None and self.bounds_seen:
            for start, end in demos.episode_bounds():
                self.observe_returns(demos.rewards[start:end])

    def observe_returns(self, rewards: np.ndarray) -> None:
        """Fold one episode's ``(T, m)`` rewards into the range of returns seen (:func:`suffix_returns`) and
        tighten the targets' upper clamp to it (:func:`seen_upper_bound`; with ``seen_bound_margin``)."""
        g = suffix_returns(rewards, self.config.gamma)
        low, high = g.min(axis=0), g.max(axis=0)
        if self.seen_returns is not None:
            low, high = np.minimum(low, self.seen_returns[0]), np.maximum(high, self.seen_returns[1])
        self.seen_returns = np.stack([low, high])
        self.set_target_clamp()

    def set_target_clamp(self) -> None:
        """The targets' clamp in the learner's units: the reward space's bounds, the upper one tightened to the
        returns seen (:func:`seen_upper_bound`) once an episode has ended, with ``seen_bound_margin``."""
        c = self.config
        high = self.q_high
        if self.bounds_seen and self.seen_returns is not None:
            high = seen_upper_bound(self.q_high, *self.seen_returns, c.seen_bound_margin)
        self._q_low_t = torch.as_tensor(self.q_low * self.reward_scale, dtype=torch.float32, device=self.device)
        self._q_high_t = torch.as_tensor(high * self.reward_scale, dtype=torch.float32, device=self.device)

    def _expert_labels(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray | None:
        """With ``demo_label_weight``, the scripted demonstrators' actions in the states about to be stepped
        (:func:`mope.agent.demonstrations.label_actions`, DAgger); else None."""
        if not self.config.demo_label_weight:
            return None
        return label_actions(self.config.env_id, obs, prefs, self.envs)

    def _greedy_trace(self, obs: np.ndarray, prefs: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """Which of the actions just taken were greedy: those act() did not explore, and the explored ones that
        equal the greedy action anyway (one forward pass over the explored rows)."""
        explored = self._explored if self._explored is not None else np.ones(len(actions), dtype=bool)
        greedy = ~explored
        if explored.any():
            best = self._greedy if self._greedy is not None else np.full(len(actions), -1)
            missing = explored & (best < 0)  # act() did not compute them (a subclass's act, say)
            if missing.any():
                best = best.copy()
                best[missing] = self.greedy_actions(obs[missing], prefs[missing])
            greedy[explored] = actions[explored] == best[explored]
        return greedy

    @torch.no_grad()
    def store_episode_returns(self, episode: Episode, terminated: bool) -> None:
        """At an episode's end: the greedy-tail return of each of its transitions under the episode's preference
        (:func:`mope.agent.losses.greedy_tail_returns`, values of the target network, learner's units), into the
        buffer. A tail the time limit cut ends on ``V(s_T)``, or with ``return_timeout_bootstrap=False`` at the limit:
        a greedy policy that loops until the limit then gets the return it really had, not one propped up by its own
        stale values (docs/results/return-timeouts)."""
        slots = np.asarray(episode.slots, dtype=np.int64)
        if len(slots) == 0:
            return
        w = self._tensor(episode.pref)[None].expand(len(slots), -1)
        q = self.target_net(self._tensor(self.buffer.next_obs[slots]), w)  # (T, A, m)
        best = torch.einsum("tm,tam->ta", w, q).argmax(dim=1)
        values = q[torch.arange(len(slots), device=q.device), best].cpu().numpy()
        returns = losses.greedy_tail_returns(self.buffer.rewards[slots] * self.reward_scale, values,
                                             np.asarray(episode.greedy, dtype=bool),
                                             terminated or not self.config.return_timeout_bootstrap, self.config.gamma)
        self.buffer.set_returns(slots, returns, self.global_step)

    def _start_episode(self, i: int) -> Episode:
        """Reset training env ``i`` (seeded by the count of episodes started) and draw the episode's preference
        from the sampler (which counts it: preference exploration sees every env's draws)."""
        seed = self.config.seed + self.episodes_started
        self.episodes_started += 1
        obs, _ = self.envs[i].reset(seed=seed)
        return Episode(seed, self.pref_sampler.sample(self.rng), obs)

    def train(self, total_timesteps: int | None = None, eval_env: gym.Env | None = None,
              eval_every: int | None = None, callback: Any = None, progress: bool = False
              ) -> list[dict[str, float]]:
        """Train for ``total_timesteps`` environment steps (default ``config.total_steps``).

        Args:
            total_timesteps: Steps to run now (training continues from ``global_step``).
            eval_env: If given, evaluate with the paper's protocol every ``eval_every`` steps and at the end.
            eval_every: Default ``config.run.eval_every``.
            callback: A :class:`mope.agent.runner.Callback` (or a list of them) called at every step.
            progress: Show a progress bar with the latest CR.

        The episode in progress carries over from one call to the next, so ``train(500)`` twice equals
        ``train(1000)`` (evaluations aside).

        Returns:
            The evaluation records (step, wall seconds and every metric of :class:`~mope.evaluation.Evaluator`).
        """
        from mope.agent.runner import train_with_evaluation

        return train_with_evaluation(self, total_timesteps, eval_env, eval_every, callback, progress)
