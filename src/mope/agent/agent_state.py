"""Saving and loading an agent: its weights, its whole training state, and the environment it was trained on.

:class:`AgentState` is the base class of :class:`mope.agent.agent.MoPE`: everything about checkpoints lives here, so
the agent module holds only acting and learning.

A checkpoint stores the config, the networks and optimizers, the preference counts, the step counters and RNG
states, and (``include_buffer=True``) the replay buffer and the episode in progress. It also stores how to
rebuild the environment: Gymnasium's ``EnvSpec`` of the environment, wrappers included, when every wrapper
records its arguments (as ``mope.envs.DiscreteActions`` does). A checkpoint of an environment that cannot be
rebuilt that way loads only with ``env=`` given, and says so.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from mope.agent.checkpoint import check_compatible, load_checkpoint, save_checkpoint
from mope.config import Config
from mope.errors import CheckpointError, EnvironmentError_, MopeError


def resolve_device(name: str) -> torch.device:
    """``cpu``, ``cuda`` or ``auto`` (cuda when available)."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise MopeError("device 'cuda' was asked for but torch sees no CUDA GPU; use --device cpu or auto")
    return torch.device(name)


def env_recipe(env: gym.Env) -> dict[str, Any]:
    """How to rebuild ``env``: ``{"spec": <EnvSpec JSON>}``, or ``{"spec": None, "why": ...}`` when it cannot be.

    An environment made by ``gymnasium.make`` / ``mo_gymnasium.make`` and wrapped only by wrappers that record
    their constructor arguments (``gymnasium.utils.RecordConstructorArgs``) can be rebuilt from its spec.
    """
    spec = env.spec
    if spec is None:
        return {"spec": None, "why": f"it was built by hand ({type(env.unwrapped).__name__}, not by gymnasium.make)"}
    unrecorded = [w.name for w in spec.additional_wrappers if w.kwargs is None]
    if unrecorded:
        return {"spec": None, "why": f"its wrapper {unrecorded[0]} does not record its arguments"}
    # Keyword arguments that JSON cannot hold but that are the registration's own (MO-Gymnasium registers the
    # mirrored DST map as a numpy array) are saved by name and taken from the registry again on load.
    registered = _registered_kwargs(spec)
    same = sorted(k for k, v in spec.kwargs.items()
                  if not _jsonable(v) and k in registered and _same(v, registered[k]))
    try:
        return {"spec": dataclasses.replace(spec, kwargs={k: v for k, v in spec.kwargs.items() if k not in same})
                .to_json(), "registered_kwargs": same}
    except (ValueError, TypeError) as exc:
        return {"spec": None, "why": f"its spec cannot be saved ({str(exc).splitlines()[0]})"}


def _registered_kwargs(spec: gym.envs.registration.EnvSpec) -> dict[str, Any]:
    try:
        return dict(gym.spec(spec.id).kwargs)
    except Exception:  # noqa: BLE001 - an unregistered id: nothing to take from the registry
        return {}


def _jsonable(value: Any) -> bool:
    try:
        json.dumps(value)
    except (TypeError, ValueError):
        return False
    return True


def _same(a: Any, b: Any) -> bool:
    try:
        return bool(np.array_equal(a, b)) if isinstance(a, np.ndarray) or isinstance(b, np.ndarray) else a == b
    except Exception:  # noqa: BLE001 - values that cannot be compared are not the same
        return False


def rebuild_env(saved: dict[str, Any], config: Config, path: str | Path) -> gym.Env | str:
    """The environment a checkpoint was trained on (or its id, for checkpoints that predate recipes).

    Raises:
        CheckpointError: when the checkpoint's environment cannot be rebuilt; the message says to pass ``env=``.
    """
    if "spec" not in saved:  # older checkpoints: the id is all there is
        return config.env_id
    if saved["spec"] is None:
        raise CheckpointError(
            f"checkpoint '{path}' was trained on an environment that cannot be rebuilt from the checkpoint "
            f"({saved.get('why', 'unknown reason')}); load it in Python with MoPE.load(path, env=your_env)")
    try:
        spec = gym.envs.registration.EnvSpec.from_json(saved["spec"])
        names = saved.get("registered_kwargs") or []
        if names:
            registered = gym.spec(spec.id).kwargs
            spec = dataclasses.replace(spec, kwargs={**{k: registered[k] for k in names}, **spec.kwargs})
        return gym.make(spec)
    except Exception as exc:  # noqa: BLE001 - a missing package, a removed registration, bad kwargs
        raise EnvironmentError_(f"checkpoint '{path}': its environment '{config.env_id}' could not be rebuilt "
                                f"({str(exc).splitlines()[0] if str(exc) else type(exc).__name__}); pass env=") \
            from None


@dataclass
class Episode:
    """The episode in progress in one training env.

    Attributes:
        seed: The seed of its reset (resuming replays ``actions`` from it).
        pref: Its preference omega_b, drawn by the preference sampler at the reset.
        obs: The env's current observation.
        actions: The actions taken so far.
        slots: With ``return_mix``, the buffer slots of its transitions ...
        greedy: ... and which of its actions were greedy.
        rewards: Its rewards so far.
        repeat: With ``epsilon_repeat_mu``, the steps its current random action is still to be repeated.
    """

    seed: int
    pref: np.ndarray
    obs: Any
    actions: list[int] = field(default_factory=list)
    slots: list[int] = field(default_factory=list)
    greedy: list[bool] = field(default_factory=list)
    rewards: list[np.ndarray] = field(default_factory=list)
    repeat: int = 0


class AgentState:
    """Checkpoint support for an agent with ``q_net``, ``target_net``, ``optimizer`` and the rest of MoPE's state."""

    config: Config

    @classmethod
    def class_for(cls, algo: str) -> type[Any]:
        """The class that :meth:`load` builds for a checkpoint of ``algo``; the agent overrides it."""
        return cls

    def state_dict(self, include_buffer: bool = False) -> dict[str, Any]:
        """Everything needed to act (and, with ``include_buffer``, to resume training)."""
        a: Any = self
        state: dict[str, Any] = {
            "config": a.config.to_dict(),
            "env": {"n_actions": a.n_actions, "n_objectives": a.m, "obs_shape": list(a.obs_shape),
                    **env_recipe(a.env)},
            "q_net": a.q_net.state_dict(),
            "target_net": a.target_net.state_dict(),
            "optimizer": a.optimizer.state_dict(),
            "preference_sampler": a.pref_sampler.state_dict(),
            "global_step": a.global_step,
            "episodes": a.episodes,
            "episodes_started": a.episodes_started,
            "rng": a.rng.bit_generator.state,
            "torch_rng": torch.get_rng_state(),
            "wall_s": a.wall_s,
            "eval_seconds": a.eval_seconds,
        }
        if a.discriminator is not None and a.disc_optimizer is not None:
            state["discriminator"] = a.discriminator.state_dict()
            state["disc_optimizer"] = a.disc_optimizer.state_dict()
        if a.seen_returns is not None:
            state["seen_returns"] = torch.as_tensor(a.seen_returns)
        if include_buffer:
            state["buffer"] = {k: torch.as_tensor(v) if isinstance(v, np.ndarray) else v
                               for k, v in a.buffer.state_dict().items()}
            if a._episodes is not None:
                state["episodes_in_progress"] = [
                    {"seed": ep.seed, "pref": torch.as_tensor(ep.pref),
                     "actions": torch.as_tensor(ep.actions, dtype=torch.int64),
                     "slots": torch.as_tensor(ep.slots, dtype=torch.int64),
                     "greedy": torch.as_tensor(ep.greedy, dtype=torch.bool), "repeat": ep.repeat}
                    for ep in a._episodes]
            state["last_losses"] = dict(a.last_losses)
        return state

    def save(self, path: str | Path, include_buffer: bool = False) -> Path:
        """Write a checkpoint (atomically). ``MoPE.load`` / ``EQL.load`` read it back."""
        return save_checkpoint(path, self.state_dict(include_buffer))

    @classmethod
    def load(cls, path: str | Path, env: gym.Env | None = None, **overrides: Any) -> Any:
        """Load a checkpoint written by :meth:`save`.

        The saved config decides the variant: ``MoPE.load`` returns an :class:`~mope.agent.agent.EQL` for an EQL
        checkpoint and a :class:`~mope.agent.agent.MoPE` otherwise; ``EQL.load`` refuses a checkpoint of another
        variant. ``env`` defaults to the environment the checkpoint was trained on, rebuilt from its spec.

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
        variant = getattr(cls, "variant", None)
        if getattr(cls, "strict_variant", False) and config.algo != variant:
            raise CheckpointError(f"checkpoint '{path}' holds a '{config.algo}' agent, not '{variant}'; "
                                  f"load it with MoPE.load")
        agent_cls = cls.class_for(config.algo)
        if env is None and "env_id" not in overrides:
            env = rebuild_env(data.get("env") or {}, config, path)  # type: ignore[assignment]
        agent = agent_cls(env if env is not None else config.env_id, config)
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
        a: Any = self
        a.q_net.load_state_dict(data["q_net"])
        a.target_net.load_state_dict(data["target_net"])
        a.optimizer.load_state_dict(data["optimizer"])
        if a.discriminator is not None and "discriminator" in data:
            a.discriminator.load_state_dict(data["discriminator"])
            a.disc_optimizer.load_state_dict(data["disc_optimizer"])
        a.pref_sampler.load_state_dict(data["preference_sampler"])
        a.global_step = int(data["global_step"])
        a.episodes = int(data["episodes"])
        a.episodes_started = int(data.get("episodes_started", a.episodes))
        a.rng.bit_generator.state = data["rng"]
        torch.set_rng_state(data["torch_rng"])
        a.wall_s = float(data.get("wall_s", 0.0))
        a.eval_seconds = float(data.get("eval_seconds", 0.0))
        if "seen_returns" in data:
            a.seen_returns = data["seen_returns"].numpy()
            a.set_target_clamp()
        if "buffer" in data:
            a.buffer.load_state_dict({k: v.numpy() if isinstance(v, torch.Tensor) else v
                                      for k, v in data["buffer"].items()})
            a.last_losses = dict(data.get("last_losses", {}))
        if "episodes_in_progress" in data:
            a._episodes = [a._restore_episode(i, int(ep["seed"]), ep["pref"].numpy(), ep["actions"].tolist(),
                                              ep["slots"].tolist(), ep["greedy"].tolist())
                           for i, ep in enumerate(data["episodes_in_progress"])]
            for ep, saved in zip(a._episodes, data["episodes_in_progress"], strict=True):
                ep.repeat = int(saved.get("repeat", 0))
        elif "episode" in data:  # checkpoints of one env, before n_envs: the reset seed was seed + episodes
            ep = data["episode"]
            a._episodes = [a._restore_episode(0, a.config.seed + a.episodes, ep["pref"].numpy(),
                                              ep["actions"].tolist(), ep.get("slots", torch.zeros(0)).tolist(),
                                              ep.get("greedy", torch.zeros(0)).tolist())]
            a.episodes_started = a.episodes + 1
        if a._episodes is not None and len(a._episodes) != len(a.envs):
            raise CheckpointError(f"checkpoint holds {len(a._episodes)} episodes in progress but the agent has "
                                  f"n_envs={len(a.envs)}")

    def _restore_episode(self, i: int, seed: int, pref: np.ndarray, actions: list[int], slots: list[int],
                         greedy: list[bool]) -> Any:
        """Rebuild the episode in progress in env ``i`` by replaying its actions from its seeded reset (no RNG
        draws)."""
        a: Any = self
        obs, _ = a.envs[i].reset(seed=seed)
        rewards = []
        for act in actions:
            obs, r, *_ = a.envs[i].step(int(act))
            rewards.append(np.asarray(r, dtype=np.float32))
        return Episode(seed, np.asarray(pref, dtype=np.float64), obs, [int(x) for x in actions],
                       [int(x) for x in slots], [bool(x) for x in greedy],
                       rewards)

    def __repr__(self) -> str:
        a: Any = self
        return f"{type(self).__name__}(env={a.config.env_id!r}, algo={a.algo!r}, step={a.global_step})"
