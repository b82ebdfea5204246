"""Evaluation: greedy rollouts under many preferences at once, and the metrics of one evaluation.

:func:`solutions` plays one greedy episode per preference. All running episodes are advanced together: one
forward pass of the Q-network per time step serves every episode still running.

:class:`Evaluator` fixes the evaluation protocol of the paper and Yang et al. (2019): 2,000 preferences drawn
uniformly from the simplex (a fixed set, so successive evaluations are comparable), discount 0.99, compared
with the environment's discounted convex coverage set. It also rolls out equally spaced preferences for the
expected utility (EUM). The metrics themselves live in :mod:`mope.metrics`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from mope import metrics
from mope.envs import default_ref_point, make_batched
from mope.evaluation.diagnose import reference_front
from mope.preferences import equally_spaced, sample_simplex, validate_preference

DEFAULT_MAX_STEPS = 1000
#: The most preferences one evaluation rolls out (the paper uses 2,000): beyond it, the solutions, the metrics and
#: the solutions CSV grow past what a machine holds comfortably.
MAX_EVAL_PREFS = 200_000
#: Episodes rolled out together: a bigger evaluation runs in chunks of this many, so the copies of an environment
#: that cannot be vectorised stay few.
EVAL_CHUNK = 10_000


def check_eval_prefs(n: int, what: str = "n_prefs") -> None:
    """Refuse more preferences than :data:`MAX_EVAL_PREFS` with a one-line :class:`~mope.errors.MopeError`."""
    from mope.errors import MopeError

    if n > MAX_EVAL_PREFS:
        raise MopeError(f"{what}={n} is out of range: one evaluation rolls out {MAX_EVAL_PREFS} preferences at most "
                        "(the paper uses 2000)")


class GreedyPolicy(Protocol):
    """Anything with ``greedy_actions(obs, prefs) -> actions`` (batched)."""

    def greedy_actions(self, obs: np.ndarray, prefs: np.ndarray) -> np.ndarray: ...


@dataclass
class Solutions:
    """Result of one greedy episode per preference."""

    prefs: np.ndarray  #: ``(n, m)``
    returns: np.ndarray  #: ``(n, m)`` undiscounted return vectors
    discounted: np.ndarray  #: ``(n, m)`` discounted return vectors
    lengths: np.ndarray  #: ``(n,)`` episode lengths
    terminated: np.ndarray  #: ``(n,)`` False where the episode hit the time limit
    #: ``(n, T + 1, *obs_shape)`` visited observations (after the end, the last one repeats); only with
    #: ``record_obs=True``
    observations: np.ndarray | None = None
    #: ``(n,)`` each episode's outcome where the environment reports one (the confrontation game), else None
    outcomes: np.ndarray | None = None

    def subset(self, idx: slice | np.ndarray) -> Solutions:
        """The rows ``idx`` of every field."""
        obs = None if self.observations is None else self.observations[idx]
        out = None if self.outcomes is None else self.outcomes[idx]
        return Solutions(self.prefs[idx], self.returns[idx], self.discounted[idx], self.lengths[idx],
                         self.terminated[idx], obs, out)


def solutions(agent: GreedyPolicy, env: gym.Env, prefs: np.ndarray, gamma: float,
              max_steps: int | None = None, seed: int = 0, record_obs: bool = False,
              close_loops: bool = True) -> Solutions:
    """Play one greedy episode per preference, all episodes batched.

    Args:
        agent: The policy; ``agent.greedy_actions`` is called once per time step on all running episodes.
        env: The environment (copied; it is not stepped).
        prefs: ``(n, m)`` preferences.
        gamma: Discount factor for ``discounted``.
        max_steps: Time limit; default the environment's registered limit, else 1000.
        seed: Reset seed of the first copy (copy ``i`` uses ``seed + i``) for stochastic environments.
        record_obs: Also return every visited observation (for path and diversity analyses).
        close_loops: On a deterministic batched environment with a finite state space (the vectorised
            Deep-Sea-Treasure), an episode that revisits a state under the same greedy preference repeats its
            loop until the time limit; its remaining steps are then added in closed form instead of stepped.
            Exact (tested against stepping); ignored with ``record_obs``.

    Returns:
        A :class:`Solutions`.
    """
    m = int(env.unwrapped.reward_space.shape[0])
    prefs = validate_preference(prefs, m)
    prefs = np.atleast_2d(prefs)
    n = len(prefs)
    if max_steps is None:
        max_steps = env.spec.max_episode_steps if env.spec and env.spec.max_episode_steps else DEFAULT_MAX_STEPS
    batch = make_batched(env, n, seed)
    obs = batch.reset()
    returns = np.zeros((n, m))
    discounted = np.zeros((n, m))
    lengths = np.zeros(n, dtype=np.int64)
    terminated = np.zeros(n, dtype=bool)
    running = np.arange(n)
    discount = 1.0
    history = [obs.copy()] if record_obs else None
    loops = close_loops and not record_obs and hasattr(batch, "state_index")
    if loops:
        visited = np.zeros((n, batch.n_states), dtype=bool)
        visited[running, batch.state_index(running)] = True
    for t in range(max_steps):
        actions = agent.greedy_actions(obs[running], prefs[running])
        next_obs, rew, term = batch.step(running, actions)
        obs[running] = next_obs
        returns[running] += rew
        discounted[running] += discount * rew
        lengths[running] += 1
        terminated[running] = term
        running = running[~term]
        discount *= gamma
        if history is not None:
            history.append(obs.copy())
        if loops and running.size:
            running = _close_loops(batch, running, visited, returns, discounted, lengths, max_steps - (t + 1),
                                   discount, gamma)
        if running.size == 0:
            break
    observations = np.stack(history, axis=1) if history is not None else None
    outcomes = np.asarray(batch.outcomes()) if hasattr(batch, "outcomes") else None
    return Solutions(prefs, returns, discounted, lengths, terminated, observations, outcomes)


def _chunked(parts: list[Solutions]) -> Solutions:
    """One :class:`Solutions` of the rows of ``parts``, in order."""
    if len(parts) == 1:
        return parts[0]

    def cat(name: str) -> np.ndarray | None:
        values = [getattr(p, name) for p in parts]
        return None if any(v is None for v in values) else np.concatenate(values)

    return Solutions(*(cat(f) for f in ("prefs", "returns", "discounted", "lengths", "terminated", "observations",
                                        "outcomes")))


def _close_loops(batch: Any, running: np.ndarray, visited: np.ndarray, returns: np.ndarray, discounted: np.ndarray,
                 lengths: np.ndarray, left: int, discount: float, gamma: float) -> np.ndarray:
    """End, in closed form, the running episodes back in a visited state; return the ones still running.

    A deterministic greedy episode back in a state it visited loops until the time limit: its ``left``
    remaining steps each give ``batch.loop_reward``, discounted from ``discount`` on.
    """
    state = batch.state_index(running)
    again = visited[running, state]
    visited[running, state] = True
    if not again.any():
        return running
    done = running[again]
    returns[done] += left * batch.loop_reward
    # sum of gamma^k for k = t+1 .. max_steps-1
    discounted[done] += discount * (1 - gamma**left) / (1 - gamma) * batch.loop_reward if gamma < 1 \
        else left * batch.loop_reward
    lengths[done] += left  # to the time limit
    return running[~again]


#: Ground-truth columns of an evaluation (NaN where the environment's dynamics are not known).
TRUTH_KEYS = ("path_error", "state_error", "overestimation")
#: Outcome columns of an evaluation (the confrontation game; NaN elsewhere): red wins, blue wins, red out.
OUTCOME_KEYS = {"win_share": "red_win", "loss_share": "blue_win", "out_share": "red_out"}


def outcome_shares(outcomes: np.ndarray | None) -> dict[str, float]:
    """The share of episodes with each outcome of :data:`OUTCOME_KEYS` (NaN when there are no outcomes)."""
    if outcomes is None or len(outcomes) == 0:
        return dict.fromkeys(OUTCOME_KEYS, float("nan"))
    return {key: float(np.mean(outcomes == name)) for key, name in OUTCOME_KEYS.items()}


#: Equally spaced preferences of EUM (100, as in morl-baselines).
N_EUM_PREFS = 100


class GroundTruthCheck:
    """Exact Q* of a known environment at 101 equally spaced preferences, and the diagnostic against it."""

    def __init__(self, model: Any, truth: Any) -> None:
        self.model, self.truth = model, truth

    @classmethod
    def for_env(cls, env: gym.Env, gamma: float, n_prefs: int = 101) -> GroundTruthCheck | None:
        from mope.errors import EnvironmentError_
        from mope.evaluation.diagnose import tabular_model, value_iteration

        if gamma >= 1:  # value iteration needs a discount below 1 (undiscounted loops have no finite value)
            return None
        try:
            model = tabular_model(env)
        except EnvironmentError_:
            return None
        m = model.n_objectives
        return cls(model, value_iteration(model, equally_spaced(m, n_prefs), gamma))

    def measure(self, agent: Any) -> dict[str, float]:
        """``path_error``, ``state_error`` and ``overestimation`` (mean, at the start state) of ``agent``."""
        from mope.evaluation.diagnose import agent_q, diagnose_q

        if not hasattr(agent, "q_values"):
            return dict.fromkeys(TRUTH_KEYS, float("nan"))
        d = diagnose_q(agent_q(agent, self.model, self.truth.prefs), self.model, self.truth)
        return {"path_error": d["path_error"], "state_error": d["state_error"],
                "overestimation": d["overestimation_mean"]}


class Evaluator:
    """The evaluation protocol: a fixed set of uniform preferences for CR, equally spaced ones for EUM.

    Args:
        env: An environment instance of the task (copied, never stepped).
        env_id: Its id (for the default reference point).
        gamma: Discount of the returns compared with the front (0.99 in the paper).
        n_prefs: Number of uniform preferences (2,000 in the paper).
        seed: Seed of the preference set.
        max_steps: Episode time limit.
        ref_point: Hypervolume reference point (default: :func:`mope.envs.default_ref_point`).
        n_eum_prefs: Number of equally spaced preferences for EUM (100 as in morl-baselines).
    """

    def __init__(self, env: gym.Env, env_id: str, gamma: float = 0.99, n_prefs: int = 2000, seed: int = 0,
                 max_steps: int | None = None, ref_point: np.ndarray | None = None, n_eum_prefs: int = N_EUM_PREFS
                 ) -> None:
        check_eval_prefs(n_prefs)
        self.env = env
        self.gamma = gamma
        self.m = int(env.unwrapped.reward_space.shape[0])
        self.max_steps = max_steps or (env.spec.max_episode_steps if env.spec else None) or DEFAULT_MAX_STEPS
        self.prefs = sample_simplex(n_prefs, self.m, np.random.default_rng(seed + 1_000_003))
        self.eum_prefs = equally_spaced(self.m, n_eum_prefs)
        self.front = reference_front(env, gamma)  # the published front, or the exact one where it is wrong
        #: Close deterministic loops in closed form (see :func:`solutions`); False steps them to the time limit.
        self.close_loops = True
        self.ref_point = (np.asarray(ref_point, dtype=np.float64) if ref_point is not None
                          else default_ref_point(env, env_id, gamma, self.max_steps))
        #: Exact values (:mod:`mope.evaluation.diagnose`) where the environment's dynamics are known, else None; each
        #: evaluation then also measures the greedy policy against them.
        self.ground_truth = GroundTruthCheck.for_env(env, gamma)

    @classmethod
    def from_config(cls, env: gym.Env, config: Any, n_prefs: int | None = None, seed: int | None = None
                    ) -> Evaluator:
        """The evaluator of a run: its environment, discount, preference count, seed, time limit and reference point.

        Args:
            env: An environment instance of the task.
            config: The run's :class:`~mope.config.Config`.
            n_prefs: Uniform preferences (default ``config.run.eval_prefs``).
            seed: Seed of the preference set (default ``config.seed``).
        """
        c = config
        return cls(env, c.env_id, c.gamma, c.run.eval_prefs if n_prefs is None else n_prefs,
                   c.seed if seed is None else seed, c.max_episode_steps, c.run.ref_point)

    def evaluate(self, agent: GreedyPolicy, record_obs: bool = False) -> tuple[dict[str, float], Solutions]:
        """Roll out every preference greedily and compute the metrics.

        Returns:
            ``(metrics, solutions)``: CR, precision, recall, optimal_share, HV and cardinality on the uniform
            set; EUM, its optimum and gap on the equally spaced set; the share of episodes that hit the time
            limit; and the uniform-set :class:`Solutions`.
        """
        all_prefs = np.concatenate([self.prefs, self.eum_prefs])
        chunk = len(all_prefs) if record_obs else EVAL_CHUNK  # recorded paths of chunks could differ in length
        sols = _chunked([solutions(agent, self.env, all_prefs[i:i + chunk], self.gamma, self.max_steps, seed=i,
                                   record_obs=record_obs, close_loops=self.close_loops)
                         for i in range(0, len(all_prefs), chunk)])
        n = len(self.prefs)
        uni = sols.subset(slice(0, n))
        result = metrics.evaluate_front(uni.discounted, uni.prefs, true_front=self.front, ref_point=self.ref_point)
        eq_prefs, eq_returns = sols.prefs[n:], sols.discounted[n:]
        result["eum"] = metrics.expected_utility(eq_returns, eq_prefs)
        if self.front is not None:
            result["eum_optimal"] = float(np.mean(metrics.optimal_utility(eq_prefs, self.front)))
            result["eum_gap"] = result["eum_optimal"] - result["eum"]
        result["timeout_share"] = float(np.mean(~uni.terminated))
        result.update(self.ground_truth.measure(agent) if self.ground_truth is not None else
                      dict.fromkeys(TRUTH_KEYS, float("nan")))
        result.update(outcome_shares(uni.outcomes))
        return result, uni
