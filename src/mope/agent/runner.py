"""The training loop and its callbacks (Stable-Baselines3's seams: collect, train, callbacks).

:func:`train` is the whole loop: one environment step, the updates, the per-step housekeeping, then the
callback. Everything else a run needs (periodic evaluation, the progress bar, checkpoints, interval statistics,
stopping on a signal) is a :class:`Callback`; :class:`CallbackList` runs several as one.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Protocol

import gymnasium as gym

from mope.config import Config
from mope.errors import MopeError

if TYPE_CHECKING:
    from mope.evaluation.evaluator import Evaluator


class Agent(Protocol):
    """What the loop and the callbacks use of an agent (:class:`mope.agent.agent.MoPE` is one): they are typed on
    this, so the loop needs nothing of the agent's module."""

    config: Config
    global_step: int
    wall_s: float
    eval_seconds: float
    epsilon: float
    buffer: Any
    last_solutions: Any

    def collect_step(self) -> None: ...

    def learn_step(self) -> dict[str, float] | None: ...

    def end_step(self) -> None: ...

    def pretrain(self) -> Any: ...


def will_pretrain(agent: Agent) -> bool:
    """Whether :func:`train` starts with DQfD's pre-training: ``demo_pretrain_steps`` > 0 and only demonstrations
    in replay so far (a fresh agent; a resumed one has already pre-trained)."""
    return bool(getattr(agent.config, "demo_pretrain_steps", 0)) and agent.global_step == 0 \
        and agent.buffer.reserved > 0 and len(agent.buffer) == agent.buffer.reserved


class Callback:
    """Hooks of :func:`train`. Return False from :meth:`on_step` to stop training at that step boundary."""

    def on_training_start(self, agent: Agent, total_steps: int) -> None:
        """Before the first step of a :func:`train` call."""

    def on_step(self, agent: Agent, stats: dict[str, float] | None) -> bool:
        """After each environment step, its updates (``stats`` of the last one, or None) and housekeeping."""
        return True

    def on_training_end(self, agent: Agent, stopped: bool) -> None:
        """After the last step; ``stopped`` when a callback ended training early."""


class CallbackList(Callback):
    """Several callbacks run in order as one; training stops when any of them asks to."""

    def __init__(self, callbacks: Sequence[Callback]) -> None:
        self.callbacks = [c for c in callbacks if c is not None]

    def on_training_start(self, agent: Agent, total_steps: int) -> None:
        for c in self.callbacks:
            c.on_training_start(agent, total_steps)

    def on_step(self, agent: Agent, stats: dict[str, float] | None) -> bool:
        keep_going = True
        for c in self.callbacks:
            keep_going = c.on_step(agent, stats) and keep_going
        return keep_going

    def on_training_end(self, agent: Agent, stopped: bool) -> None:
        for c in self.callbacks:
            c.on_training_end(agent, stopped)


def as_callback(callback: Callback | Sequence[Callback] | None) -> Callback:
    """A single :class:`Callback` from one, a list of them, or None."""
    if callback is None:
        return Callback()
    if isinstance(callback, Callback):
        return callback
    if isinstance(callback, (list, tuple)):
        return CallbackList(callback)
    raise MopeError(f"callback {callback!r} is not a mope.agent.runner.Callback (or a list of them)")


def train(agent: Agent, total_steps: int, callback: Callback | Sequence[Callback] | None = None) -> bool:
    """Run ``total_steps`` environment steps of ``agent``, continuing from ``agent.global_step``.

    One step: :meth:`~mope.agent.agent.MoPE.collect_step` (act, step the ``n_envs`` environments, store their
    transitions), :meth:`~mope.agent.agent.MoPE.learn_step` (the updates, every ``train_freq``-th step),
    :meth:`~mope.agent.agent.MoPE.end_step` (target network, learning rate), then ``callback.on_step``. With
    ``n_envs`` > 1 a step advances ``global_step`` by ``n_envs``, so a call may end up to ``n_envs - 1`` env
    steps past ``total_steps``. The training wall time (evaluations included) accumulates in ``agent.wall_s``.

    Returns:
        True when all steps ran, False when a callback stopped training early.
    """
    if total_steps < 1:
        raise MopeError(f"total_timesteps={total_steps} is out of range: must be >= 1")
    cb = as_callback(callback)
    t0 = time.perf_counter()
    agent.train_started = t0  # type: ignore[attr-defined] - lets callbacks report wall time mid-call
    cb.on_training_start(agent, total_steps)
    if will_pretrain(agent):
        agent.pretrain()
    end = agent.global_step + total_steps
    stopped = False
    while agent.global_step < end:
        agent.collect_step()
        stats = agent.learn_step()
        agent.end_step()
        if not cb.on_step(agent, stats):
            stopped = True
            break
    if stopped:
        agent.wall_s += time.perf_counter() - t0
    cb.on_training_end(agent, stopped)
    if not stopped:
        agent.wall_s += time.perf_counter() - t0
    return not stopped


def crossed_now(agent: Agent, every: int) -> bool:
    """Whether the step just taken (``n_envs`` env steps) passed a multiple of ``every`` env steps: what the
    callbacks' "every N steps" means with several environments."""
    step, n = agent.global_step, agent.config.n_envs
    return step // every > (step - n) // every


def wall_seconds(agent: Agent) -> float:
    """Training wall seconds so far, the current :func:`train` call included."""
    started = getattr(agent, "train_started", None)
    return agent.wall_s + (time.perf_counter() - started if started is not None else 0.0)


class EvalCallback(Callback):
    """Evaluate every ``every`` steps and at the end (unless stopped); keeps the records.

    Args:
        evaluator: The evaluation protocol.
        every: Steps between evaluations (0: only at the end).
        on_record: Called with ``(agent, record)`` after each evaluation.
    """

    def __init__(self, evaluator: Evaluator, every: int,
                 on_record: Callable[[Agent, dict[str, float]], None] | None = None) -> None:
        self.evaluator = evaluator
        self.every = every
        self.on_record = on_record
        self.records: list[dict[str, float]] = []
        #: Seconds spent evaluating (the training wall time includes them).
        self.seconds = 0.0

    def evaluate(self, agent: Agent) -> dict[str, float]:
        t0 = time.perf_counter()
        train_s = wall_seconds(agent) - agent.eval_seconds  # training only, up to this evaluation
        res, agent.last_solutions = self.evaluator.evaluate(agent)
        dt = time.perf_counter() - t0
        self.seconds += dt
        agent.eval_seconds += dt
        rec = {"step": agent.global_step, "wall_s": wall_seconds(agent), "train_s": train_s, **res}
        self.records.append(rec)
        if self.on_record is not None:
            self.on_record(agent, rec)
        return rec

    def on_step(self, agent: Agent, stats: dict[str, float] | None) -> bool:
        if self.every and crossed_now(agent, self.every):
            self.evaluate(agent)
        return True

    def on_training_end(self, agent: Agent, stopped: bool) -> None:
        if not stopped and (not self.records or self.records[-1]["step"] != agent.global_step):
            self.evaluate(agent)


class ProgressBar(Callback):
    """A tqdm bar over the steps of one :func:`train` call, with the latest CR and EUM of ``eval_callback``."""

    def __init__(self, eval_callback: EvalCallback | None = None, desc: str | None = None) -> None:
        self.eval_callback = eval_callback
        self.desc = desc
        self.bar: Any = None
        self._shown = 0

    def on_training_start(self, agent: Agent, total_steps: int) -> None:
        from tqdm.auto import tqdm

        c = agent.config
        self.bar = tqdm(total=total_steps, desc=self.desc or f"{c.algo} {c.env_id}", unit="step",
                        dynamic_ncols=True, mininterval=0.5)
        if will_pretrain(agent):  # the updates before the first env step, so that the bar does not look stuck
            self.bar.set_postfix_str(f"pre-training on the demonstrations: {c.demo_pretrain_steps} updates")

    def on_step(self, agent: Agent, stats: dict[str, float] | None) -> bool:
        if self.bar.n == 0:
            self.bar.set_postfix_str("", refresh=False)
        self.bar.update(agent.config.n_envs)
        records = self.eval_callback.records if self.eval_callback is not None else []
        if len(records) != self._shown:
            self._shown = len(records)
            self.bar.set_postfix(cr=f"{records[-1]['cr']:.3f}", eum=f"{records[-1]['eum']:.2f}", refresh=False)
        return True

    def on_training_end(self, agent: Agent, stopped: bool) -> None:
        self.bar.close()


class StopWhen(Callback):
    """Stop training at the next step boundary once ``predicate()`` is true (e.g. a signal arrived)."""

    def __init__(self, predicate: Callable[[], bool]) -> None:
        self.predicate = predicate

    def on_step(self, agent: Agent, stats: dict[str, float] | None) -> bool:
        return not self.predicate()


class IntervalStats(Callback):
    """Average the update statistics over every ``every`` steps and hand each average to ``sink``.

    Each row has ``step``, ``updates`` (how many updates it averages), ``epsilon`` and the mean of every
    statistic :meth:`~mope.agent.agent.MoPE.update` returns (losses, |TD|, mean and max Q, MI bonus), and, where
    training episodes ended in the interval, the agent's ``pop_episode_stats()`` (their count, mean length, share
    ended in a terminal state and mean return per objective).
    """

    def __init__(self, every: int, sink: Callable[[dict[str, float]], None]) -> None:
        self.every = every
        self.sink = sink
        self._sums: dict[str, float] = {}
        self._count = 0

    def on_step(self, agent: Agent, stats: dict[str, float] | None) -> bool:
        if stats:
            self._count += 1
            for k, v in stats.items():
                self._sums[k] = self._sums.get(k, 0.0) + v
        if crossed_now(agent, self.every):
            self.flush(agent)
        return True

    def flush(self, agent: Agent) -> None:
        """Hand the interval so far to the sink now (a run stopped between two rows: its last row averages the
        ``updates`` made since the previous one, and the resumed run's next row the rest)."""
        if not self._count:
            return
        episodes = agent.pop_episode_stats() if hasattr(agent, "pop_episode_stats") else {}
        row = {"step": agent.global_step, "updates": self._count, "epsilon": agent.epsilon,
               **{k: v / self._count for k, v in self._sums.items()}, **episodes}
        self._sums, self._count = {}, 0
        self.sink(row)


def train_with_evaluation(agent: Agent, total_timesteps: int | None = None, eval_env: gym.Env | None = None,
                          eval_every: int | None = None, callback: Any = None, progress: bool = False
                          ) -> list[dict[str, float]]:
    """What :meth:`mope.agent.agent.MoPE.train` does: :func:`train` with evaluation and a progress bar as callbacks."""
    from mope.evaluation.evaluator import Evaluator

    c = agent.config
    total = c.total_steps if total_timesteps is None else int(total_timesteps)
    every = c.run.eval_every if eval_every is None else eval_every
    evaluating = EvalCallback(Evaluator.from_config(eval_env, c), every) if eval_env is not None else None
    callbacks: list[Callback] = [cb for cb in (evaluating,) if cb is not None]
    if progress:
        callbacks.insert(0, ProgressBar(evaluating))
    callbacks.append(as_callback(callback))
    train(agent, total, callbacks)
    return evaluating.records if evaluating is not None else []


__all__ = ["Callback", "CallbackList", "EvalCallback", "IntervalStats", "ProgressBar", "StopWhen", "crossed_now",
           "train", "train_with_evaluation", "wall_seconds"]
