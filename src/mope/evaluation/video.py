"""Record one greedy rollout as an animated GIF (``mope act CHECKPOINT --pref ... --video out.gif``).

Works for any environment that renders ``rgb_array`` frames: the Robot Confrontation Game, Deep-Sea-Treasure
and the other MO-Gymnasium environments. The policy can be a mope agent (``act(obs, pref)``), a
Stable-Baselines3 model (``predict(obs)``; the preference is then ignored: one model is one preference) or any
callable ``obs -> action``.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from mope.errors import MopeError


class VideoError(MopeError):
    """A rollout cannot be recorded (no ``rgb_array`` rendering, a bad path, an unusable policy)."""


def _action_fn(policy: Any, pref: np.ndarray | None, space: Any = None) -> Callable[[np.ndarray], Any]:
    if hasattr(policy, "act") and hasattr(policy, "greedy_actions"):
        if pref is None:
            raise VideoError("a preference is needed to play a preference-conditioned agent (e.g. --pref 0.5,0.5)")
        return lambda obs: policy.act(obs, pref)
    if hasattr(policy, "predict"):
        own = getattr(policy, "action_space", None)
        if isinstance(space, gym.spaces.Box) and isinstance(own, gym.spaces.Box) and own.shape == space.shape \
                and not (np.allclose(own.low, space.low) and np.allclose(own.high, space.high)):
            from mope.paper.ppo import rescale_to_box  # a model trained through RescaleAction (mope's PPO)

            return lambda obs: rescale_to_box(policy.predict(obs, deterministic=True)[0], space)
        return lambda obs: policy.predict(obs, deterministic=True)[0]
    if callable(policy):
        return policy
    raise VideoError(f"cannot play {type(policy).__name__}: need a mope agent, an SB3 model or a callable")


def record_video(policy: Any, env_id: str, pref: Any, path: str | Path, seed: int = 0,
                 max_steps: int | None = None, fps: int | None = None, **env_kwargs: Any) -> dict[str, Any]:
    """Play one episode greedily under ``pref`` and write its frames as a GIF.

    Args:
        policy: A mope agent, an SB3 model or a callable ``obs -> action``.
        env_id: The environment id (built with ``render_mode="rgb_array"``).
        pref: The preference (for a mope agent; validated against the reward dimension).
        path: Output ``.gif``.
        seed: Reset seed of the episode.
        max_steps: Episode length limit (default the registered limit, else 1000).
        fps: Frames per second (default the environment's ``render_fps``, else 10).
        **env_kwargs: Passed to the environment's constructor.

    Returns:
        ``{"path", "frames", "return" (undiscounted vector), "outcome" (``info["outcome"]`` if any)}``.
    """
    import imageio.v3 as iio

    from mope.preferences import validate_preference

    out = check_video_path(path)
    quiet_media()
    env = _rendering_env(env_id, env_kwargs)
    m = int(env.unwrapped.reward_space.shape[0])
    w = validate_preference(pref, m) if pref is not None else None
    act = _action_fn(policy, w, env.action_space)
    limit = max_steps or (env.spec.max_episode_steps if env.spec else None) or 1000
    try:
        obs, info = env.reset(seed=seed)
        frames = [_frame(env, env_id)]
        total = np.zeros(m)
        for _ in range(limit):
            obs, r, term, trunc, info = env.step(act(obs))
            total += np.asarray(r, dtype=np.float64)
            frames.append(_frame(env, env_id))
            if term or trunc:
                break
        rate = fps or env.metadata.get("render_fps") or 10
    finally:
        env.close()
    # encoded in memory, then written: a failed write cannot leave imageio's writer to fail again when collected
    data = iio.imwrite("<bytes>", np.stack(frames), extension=".gif", duration=1000.0 / rate, loop=0)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_bytes(data)
    except OSError as exc:
        raise VideoError(f"cannot write '{out}': {exc.strerror or exc}") from None
    return {"path": out, "frames": len(frames), "return": total, "outcome": info.get("outcome")}


def quiet_media() -> None:
    """Keep pygame (the rendering of several environments) from probing sound cards and displays: no ALSA or
    ``XDG_RUNTIME_DIR`` lines, no greeting. Takes effect when pygame is first imported; values already set stay."""
    for key, value in (("SDL_AUDIODRIVER", "dummy"), ("SDL_VIDEODRIVER", "dummy"),
                       ("PYGAME_HIDE_SUPPORT_PROMPT", "1"), ("AUDIODEV", "null")):
        os.environ.setdefault(key, value)


def check_video_path(path: str | Path) -> Path:
    """The video's path, refused (:class:`VideoError`) unless it ends in ``.gif`` and can be written."""
    out = Path(path)
    if out.suffix.lower() != ".gif":
        raise VideoError(f"video path '{out}' must end in .gif")
    _check_writable(out)
    return out


def _check_writable(out: Path) -> None:
    """Refuse, before the episode is played, a video path that is a folder or lies in a folder that cannot be made
    or written."""
    try:
        if out.is_dir():
            raise VideoError(f"video path '{out}' is a folder; give a file name ending in .gif")
        base = next(p for p in (out.parent, *out.parent.parents) if p.exists())
        if not base.is_dir():
            raise VideoError(f"cannot write '{out}': '{base}' is a file, not a folder")
        probe = base / f".mope-write-test-{os.getpid()}"
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        raise VideoError(f"cannot write '{out}': {exc.strerror or exc}") from None


def _rendering_env(env_id: str, env_kwargs: dict[str, Any]) -> Any:
    """The environment built with ``render_mode="rgb_array"``, or a :class:`VideoError` saying why not."""
    import mo_gymnasium as mo_gym

    import mope.envs.confrontation  # noqa: F401 - registers the confrontation ids
    from mope.envs import registered_ids
    from mope.errors import suggest

    if env_id not in gym.registry:
        raise VideoError(f"unknown environment '{env_id}'{suggest(env_id, registered_ids())}")
    try:
        with warnings.catch_warnings():  # an env without rgb_array warns here; the check below says it plainly
            warnings.filterwarnings("ignore", message=".*not in the possible render_modes.*")
            env = mo_gym.make(env_id, render_mode="rgb_array", **env_kwargs)
    except Exception as exc:  # noqa: BLE001 - missing dependencies or bad kwargs of the user's environment
        raise VideoError(f"environment '{env_id}' could not be created for rendering: {exc}") from None
    if "rgb_array" not in env.metadata.get("render_modes", []):
        env.close()
        raise VideoError(f"environment '{env_id}' cannot render rgb_array frames, so no video can be recorded")
    return env


def _frame(env: Any, env_id: str) -> np.ndarray:
    frame = env.render()
    if frame is None or np.ndim(frame) != 3:
        raise VideoError(f"environment '{env_id}' returned no rgb_array frame, so no video can be recorded")
    return np.asarray(frame, dtype=np.uint8)
