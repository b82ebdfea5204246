"""Environments: building MO-Gymnasium environments, checking they fit the agents, and their known fronts.

``make_env`` is the one place mope creates environments (the CLI, the API, evaluation and the experiments
all go through it). Any MO-Gymnasium environment with a ``Discrete`` action space, a ``Box`` or ``Discrete``
observation space and a vector reward works without code changes.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import gymnasium as gym
import mo_gymnasium as mo_gym
import numpy as np

from mope.errors import EnvironmentError_, suggest

if TYPE_CHECKING:
    from mope.envs.batched import BatchedEnv

# MO-Gymnasium's own spaces trip this Gymnasium warning on every make(); it says nothing about the user's input.
warnings.filterwarnings("ignore", message=".*precision lowered by casting.*")

#: Hypervolume reference points used in the MORL literature (morl-baselines' examples) for known envs.
KNOWN_REF_POINTS: dict[str, tuple[float, ...]] = {
    "deep-sea-treasure-v0": (0.0, -25.0),
    "deep-sea-treasure-concave-v0": (0.0, -25.0),
    "mope/deep-sea-treasure-seabed-v0": (0.0, -25.0),
    "deep-sea-treasure-mirrored-v0": (0.0, -50.0),
    "fruit-tree-v0": (0.0,) * 6,
    "four-room-v0": (-1.0, -1.0, -1.0),
    "minecart-v0": (-1.0, -1.0, -200.0),
    "minecart-deterministic-v0": (-1.0, -1.0, -200.0),
    "resource-gathering-v0": (-1.0, -1.0, -2.0),
}


def registered_ids() -> list[str]:
    """All environment ids Gymnasium knows (MO-Gymnasium registers its own on import)."""
    return sorted(gym.registry.keys())


def make_env(env_id: str, max_episode_steps: int | None = None, **kwargs) -> gym.Env:
    """Create a multi-objective environment by id and check that mope's agents can use it.

    Args:
        env_id: A registered id such as ``deep-sea-treasure-v0``.
        max_episode_steps: Time limit; ``None`` keeps the registered one.
        **kwargs: Passed to the environment's constructor.

    Raises:
        EnvironmentError_: for an unknown id or an unsupported environment, naming it.
    """
    if env_id not in gym.registry:
        hint = suggest(env_id, registered_ids()) or "; `mope envs` lists the environments mope can use"
        raise EnvironmentError_(f"unknown environment '{env_id}'{hint}")
    try:
        env = mo_gym.make(env_id, max_episode_steps=max_episode_steps, **kwargs) if max_episode_steps \
            else mo_gym.make(env_id, **kwargs)
    except EnvironmentError_:
        raise
    except Exception as exc:  # an env whose dependencies are missing, or bad kwargs
        raise EnvironmentError_(f"environment '{env_id}' could not be created: {exc}") from None
    check_env_fits(env, env_id)
    return env


class DiscreteActions(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Give a continuous-action (``Box``) environment a ``Discrete`` action space, so EQL/MoPE can use it.

    Each dimension of the box is cut into ``bins`` evenly spaced values from ``low`` to ``high``; discrete action
    ``k`` is the ``k``-th point of the resulting grid (``bins ** d`` actions for a ``d``-dimensional box).

    Args:
        env: An environment whose action space is a bounded ``Box``.
        bins: Values per action dimension, at least 2.
    """

    def __init__(self, env: gym.Env, bins: int = 5) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, bins=bins)  # lets a checkpoint rebuild the wrapped env
        super().__init__(env)
        space = env.action_space
        if not isinstance(space, gym.spaces.Box):
            raise EnvironmentError_(f"DiscreteActions needs a Box action space, got {space}")
        if isinstance(bins, bool) or not isinstance(bins, int) or bins < 2:
            raise EnvironmentError_(f"bins={bins!r} is out of range: must be an integer >= 2")
        low, high = space.low.reshape(-1), space.high.reshape(-1)
        if not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
            raise EnvironmentError_(f"DiscreteActions needs a bounded Box action space, got {space}")
        axes = [np.linspace(lo, hi, bins) for lo, hi in zip(low, high, strict=True)]
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, low.size)
        self._table = grid.astype(space.dtype).reshape(-1, *space.shape)
        self.action_space = gym.spaces.Discrete(len(self._table))

    def action(self, action: int) -> np.ndarray:
        """The box action of discrete action ``action``."""
        return self._table[int(action)]


@dataclass(frozen=True)
class EnvSpec:
    """What the agent needs to know about an environment."""

    env_id: str
    obs_space: gym.Space
    n_actions: int
    n_objectives: int
    max_episode_steps: int | None


def check_env_fits(env: gym.Env, env_id: str | None = None) -> EnvSpec:
    """Check the action, observation and reward spaces; return an :class:`EnvSpec`."""
    name = env_id or (env.spec.id if env.spec else type(env.unwrapped).__name__)
    if isinstance(env.action_space, gym.spaces.Box):
        raise EnvironmentError_(
            f"environment '{name}' has a continuous action space {env.action_space}; EQL/MoPE need discrete actions: "
            "wrap it with a discrete action wrapper, mope.envs.DiscreteActions(env, bins=5), and pass the wrapped "
            "environment to the agent, or use an environment with a Discrete action space (`mope envs` lists them)"
        )
    if not isinstance(env.action_space, gym.spaces.Discrete):
        raise EnvironmentError_(
            f"environment '{name}' has action space {env.action_space}; EQL/MoPE need a Discrete action space"
        )
    if not isinstance(env.observation_space, (gym.spaces.Box, gym.spaces.Discrete)):
        raise EnvironmentError_(
            f"environment '{name}' has observation space {env.observation_space}; mope needs Box or Discrete"
        )
    reward_space = getattr(env.unwrapped, "reward_space", None)
    if reward_space is None or not hasattr(reward_space, "shape") or len(reward_space.shape) != 1:
        raise EnvironmentError_(f"environment '{name}' has no vector reward_space; is it a MO-Gymnasium environment?")
    limit = env.spec.max_episode_steps if env.spec is not None else None
    return EnvSpec(name, env.observation_space, int(env.action_space.n), int(reward_space.shape[0]), limit)


def known_front(env: gym.Env, gamma: float) -> np.ndarray | None:
    """The environment's discounted Pareto front, if it publishes one (``pareto_front(gamma)``), else ``None``."""
    fn = getattr(env.unwrapped, "pareto_front", None)
    if fn is None:
        return None
    try:
        front = fn(gamma=gamma)
    except (NotImplementedError, TypeError):
        return None
    if front is None or len(front) == 0:
        return None
    return np.asarray(front, dtype=np.float64)


def default_ref_point(env: gym.Env, env_id: str, gamma: float, horizon: int | None) -> np.ndarray | None:
    """Hypervolume reference point: the literature's value for known envs, the env's own
    ``hv_reference_point(gamma, horizon)`` if it has one, else derived from reward bounds.

    For an unknown env with a finite ``reward_space.low``, the reference point is the worst discounted return
    ``low * sum_{t < H} gamma^t`` over the horizon ``H`` minus 1, which every achievable return dominates.
    Otherwise ``None`` (hypervolume is then reported as NaN unless the user gives ``--ref-point``).
    """
    if env_id in KNOWN_REF_POINTS:
        return np.asarray(KNOWN_REF_POINTS[env_id], dtype=np.float64)
    own = getattr(env.unwrapped, "hv_reference_point", None)
    if callable(own):  # an environment that knows its worst return (mope's confrontation game)
        return np.asarray(own(gamma, horizon), dtype=np.float64)
    low = np.asarray(env.unwrapped.reward_space.low, dtype=np.float64)
    if horizon is None or not np.all(np.isfinite(low)):
        return None
    disc = (1 - gamma**horizon) / (1 - gamma) if gamma < 1 else float(horizon)
    return np.minimum(low, 0.0) * disc - 1.0


def make_batched(env: gym.Env, n: int, seed: int = 0) -> BatchedEnv:
    """The fastest exact batched version of ``env`` available: the vectorised Deep-Sea-Treasure or game, else
    ``n`` copies stepped one by one."""
    from mope.envs.batched import DeepSeaTreasureBatch, EnvList
    from mope.envs.confrontation_batch import ConfrontationBatch

    if DeepSeaTreasureBatch.supports(env):
        return DeepSeaTreasureBatch(env, n)
    if ConfrontationBatch.supports(env):
        return ConfrontationBatch(env, n, seed)
    return EnvList(env, n, seed)


from mope.envs import confrontation  # noqa: E402, F401 - registers mope/RobotConfrontation*-v0
from mope.envs.dst import SEABED_ID  # noqa: E402

if SEABED_ID not in gym.registry:
    gym.register(SEABED_ID, entry_point="mope.envs.dst:SeabedDeepSeaTreasure", max_episode_steps=100)
