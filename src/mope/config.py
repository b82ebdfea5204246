"""The one configuration object shared by the CLI, the Python API and saved runs.

``Config`` holds every hyperparameter of the paper and of the training loop. ``mope train`` builds one from
its flags, ``MoPE(env, **overrides)`` builds one from keyword arguments, and every run folder and
checkpoint stores ``Config.to_dict()``; :meth:`Config.from_dict` reads it back. Values are validated when
the object is built, with one-line errors that name the bad value.

Where the paper is silent, the default is what Yang et al. (2019) or morl-baselines use on
Deep-Sea-Treasure, and the field's docstring says so (see ``docs/design.md``).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mope.errors import ConfigError, suggest

#: Algorithm name -> (experience_exploration, preference_exploration). Fig. 2 of the paper.
ALGOS: dict[str, tuple[bool, bool]] = {
    "eql": (False, False),
    "ee": (True, False),
    "pe": (False, True),
    "mope": (True, True),
}

ENVELOPE_PREFS = ("relabel", "batch", "both", "own")
DEVICES = ("cpu", "cuda", "auto")


@dataclass
class Config:
    """All settings of one training run.

    Attributes are grouped as: run, EQL core, prioritized replay, experience exploration (EE),
    preference exploration (PE) and evaluation. ``algo`` is derived from the two exploration switches.
    """

    # --- run -------------------------------------------------------------------------------------------
    env_id: str = "deep-sea-treasure-v0"
    seed: int = 0
    total_steps: int = 20_000
    device: str = "cpu"
    #: torch intra-op threads; 0 leaves torch's default. 1 is fastest for these small networks on 2 cores.
    torch_threads: int = 1
    #: Episode time limit; ``None`` uses the limit the environment registers (100 on Deep-Sea-Treasure).
    max_episode_steps: int | None = None

    #: How observations enter the networks: "scale" (a bounded Box to [0, 1]: the paper's (x, y) input) or
    #: "onehot" (each coordinate of an integer Box one-hot encoded).
    obs_encoding: str = "scale"

    # --- EQL core (paper eq. 4; Yang et al. 2019) ------------------------------------------------------------
    gamma: float = 0.99
    hidden_sizes: tuple[int, ...] = (64, 128, 128, 64)
    learning_rate: float = 1e-3
    batch_size: int = 32
    buffer_size: int = 20_000
    learning_starts: int = 200
    #: Gradient updates per environment step.
    gradient_steps: int = 1
    #: Hard target-network copy every this many environment steps (Yang et al. use 100).
    target_update_freq: int = 100
    #: Weight of the auxiliary loss: L = L^A + lb_weight * L^B. The paper uses 1.
    lb_weight: float = 1.0
    max_grad_norm: float | None = 10.0
    #: Pick (a*, w'*) of the envelope target with the online network, read the value from the target network
    #: (double Q-learning). Not in the paper; see docs/design.md for why it is on by default.
    double_q: bool = True
    #: Clamp the targets y to the range of returns the reward bounds allow (reward_space low/high and gamma).
    #: Not in the paper; see docs/design.md.
    clip_targets: bool = True
    epsilon_start: float = 1.0
    epsilon_end: float = 0.05
    epsilon_decay_steps: int = 10_000
    #: Preferences per sampled transition (N_omega). EQL draws them uniformly from the simplex, shared by
    #: the batch (Yang et al.'s ``weight_num``); EE draws them within ``sigma_omega`` of the transition's own.
    n_omega: int = 64

    # --- prioritized replay (Schaul et al. 2016) ------------------------------------------------------------
    per: bool = True
    per_alpha: float = 0.6
    per_beta_start: float = 0.4
    per_eps: float = 0.01

    # --- experience exploration (EE): relabeling, eq. 5-7 ----------------------------------------------------
    experience_exploration: bool = True
    sigma_omega: float = 0.04
    #: Preference set the envelope max runs over: the transition's own relabeled set ("relabel"),
    #: the acting preferences of the whole batch ("batch"), or both; "own" switches the envelope off (each row maxes
    #: over actions at its own preference only: an ablation, like morl-baselines' ``envelope=False``).
    envelope_prefs: str = "relabel"
    #: Weight alpha of the mutual-information term in the priority (eq. 7).
    mi_alpha: float = 0.1
    disc_hidden: tuple[int, ...] = (64, 64)
    disc_learning_rate: float = 1e-3

    # --- preference exploration (PE) ---------------------------------------------------------------------------
    preference_exploration: bool = True
    n_intervals: int = 10
    #: The constant in p(omega) ~ (N_i + c)^(-1/2); the paper uses 0.01.
    pe_count_offset: float = 0.01

    # --- evaluation ------------------------------------------------------------------------------------------
    eval_every: int = 1_000
    eval_prefs: int = 2_000
    #: Reference point for hypervolume; ``None`` uses the environment's documented default.
    ref_point: tuple[float, ...] | None = None
    checkpoint_every: int = 5_000

    extra: dict[str, Any] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._check_types()
        self.hidden_sizes = tuple(self.hidden_sizes)
        self.disc_hidden = tuple(self.disc_hidden)
        if self.ref_point is not None:
            self.ref_point = tuple(float(x) for x in self.ref_point)
        self.validate()

    def _check_types(self) -> None:
        """Raise :class:`ConfigError` for a value of the wrong type (a quoted number, a bool for a count, ...)."""

        def is_int(x: Any) -> bool:
            return isinstance(x, int) and not isinstance(x, bool)

        def is_num(x: Any) -> bool:
            return isinstance(x, (int, float)) and not isinstance(x, bool)

        checks: dict[str, tuple[Callable[[Any], bool], str]] = {
            "int": (is_int, "an integer"),
            "float": (is_num, "a number"),
            "bool": (lambda x: isinstance(x, bool), "true or false"),
            "str": (lambda x: isinstance(x, str), "a string"),
            "int | None": (lambda x: x is None or is_int(x), "an integer or null"),
            "float | None": (lambda x: x is None or is_num(x), "a number or null"),
            "tuple[int, ...]": (lambda x: isinstance(x, (list, tuple)) and all(is_int(v) for v in x),
                                "a list of integers"),
            "tuple[float, ...] | None": (lambda x: x is None or (isinstance(x, (list, tuple))
                                                                and all(is_num(v) for v in x)),
                                         "a list of numbers or null"),
        }
        for f in dataclasses.fields(self):
            if f.type not in checks:
                continue
            ok, what = checks[f.type]
            value = getattr(self, f.name)
            if not ok(value):
                raise ConfigError(f"{f.name}={value!r} is not {what}")

    # ------------------------------------------------------------------------------------------------------
    @property
    def algo(self) -> str:
        """Name of the variant: ``eql``, ``ee``, ``pe`` or ``mope``."""
        flags = (self.experience_exploration, self.preference_exploration)
        return next(name for name, f in ALGOS.items() if f == flags)

    @classmethod
    def for_algo(cls, algo: str, **overrides: Any) -> Config:
        """Build the config of a named variant (``eql``, ``ee``, ``pe``, ``mope``) with overrides."""
        if algo not in ALGOS:
            raise ConfigError(f"unknown algorithm '{algo}'{suggest(algo, ALGOS)}; choose one of {', '.join(ALGOS)}")
        ee, pe = ALGOS[algo]
        overrides.setdefault("experience_exploration", ee)
        overrides.setdefault("preference_exploration", pe)
        if (overrides["experience_exploration"], overrides["preference_exploration"]) != (ee, pe):
            raise ConfigError(f"algorithm '{algo}' contradicts the exploration switches given with it")
        return cls.from_dict(overrides)

    def replace(self, **changes: Any) -> Config:
        """Return a copy with ``changes`` applied (validated)."""
        return self.from_dict({**self.to_dict(), **changes})

    # ------------------------------------------------------------------------------------------------------
    def validate(self) -> None:
        """Raise :class:`ConfigError` naming the first out-of-range value."""

        def need(ok: bool, name: str, allowed: str) -> None:
            if not ok:
                raise ConfigError(f"{name}={getattr(self, name)!r} is out of range: {allowed}")

        def finite(x: float) -> bool:
            return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

        need(isinstance(self.env_id, str) and bool(self.env_id), "env_id", "must be a non-empty string")
        need(isinstance(self.seed, int) and self.seed >= 0, "seed", "must be an integer >= 0")
        need(isinstance(self.total_steps, int) and self.total_steps >= 1, "total_steps", "must be >= 1")
        need(self.device in DEVICES, "device", f"choose one of {', '.join(DEVICES)}")
        need(self.obs_encoding in ("scale", "onehot"), "obs_encoding", "choose one of scale, onehot")
        need(isinstance(self.torch_threads, int) and self.torch_threads >= 0, "torch_threads", "must be >= 0")
        need(self.max_episode_steps is None or self.max_episode_steps >= 1, "max_episode_steps",
             "must be >= 1 or None")
        need(finite(self.gamma) and 0.0 < self.gamma <= 1.0, "gamma", "must lie in (0, 1]")
        need(len(self.hidden_sizes) >= 1 and all(h >= 1 for h in self.hidden_sizes), "hidden_sizes",
             "must be one or more positive layer widths")
        need(finite(self.learning_rate) and self.learning_rate > 0, "learning_rate", "must be > 0")
        need(isinstance(self.batch_size, int) and self.batch_size >= 1, "batch_size", "must be >= 1")
        need(isinstance(self.buffer_size, int) and self.buffer_size >= self.batch_size, "buffer_size",
             f"must be >= batch_size ({self.batch_size})")
        need(isinstance(self.learning_starts, int) and self.learning_starts >= 0, "learning_starts",
             "must be >= 0")
        need(isinstance(self.gradient_steps, int) and self.gradient_steps >= 1, "gradient_steps", "must be >= 1")
        need(isinstance(self.target_update_freq, int) and self.target_update_freq >= 1, "target_update_freq",
             "must be >= 1")
        need(finite(self.lb_weight) and self.lb_weight >= 0, "lb_weight", "must be >= 0")
        need(self.max_grad_norm is None or (finite(self.max_grad_norm) and self.max_grad_norm > 0),
             "max_grad_norm", "must be > 0 or None")
        for name in ("epsilon_start", "epsilon_end"):
            need(finite(getattr(self, name)) and 0.0 <= getattr(self, name) <= 1.0, name, "must lie in [0, 1]")
        need(isinstance(self.epsilon_decay_steps, int) and self.epsilon_decay_steps >= 1, "epsilon_decay_steps",
             "must be >= 1")
        need(isinstance(self.n_omega, int) and self.n_omega >= 1, "n_omega", "must be >= 1")
        need(finite(self.per_alpha) and self.per_alpha >= 0, "per_alpha", "must be >= 0")
        need(finite(self.per_beta_start) and 0 <= self.per_beta_start <= 1, "per_beta_start", "must lie in [0, 1]")
        need(finite(self.per_eps) and self.per_eps > 0, "per_eps", "must be > 0")
        need(finite(self.sigma_omega) and self.sigma_omega > 0, "sigma_omega", "must be > 0")
        need(self.envelope_prefs in ENVELOPE_PREFS, "envelope_prefs", f"choose one of {', '.join(ENVELOPE_PREFS)}")
        need(finite(self.mi_alpha) and self.mi_alpha >= 0, "mi_alpha", "must be >= 0")
        need(len(self.disc_hidden) >= 1 and all(h >= 1 for h in self.disc_hidden), "disc_hidden",
             "must be one or more positive layer widths")
        need(finite(self.disc_learning_rate) and self.disc_learning_rate > 0, "disc_learning_rate", "must be > 0")
        need(isinstance(self.n_intervals, int) and self.n_intervals >= 1, "n_intervals", "must be >= 1")
        need(finite(self.pe_count_offset) and self.pe_count_offset > 0, "pe_count_offset", "must be > 0")
        need(isinstance(self.eval_every, int) and self.eval_every >= 0, "eval_every", "must be >= 0 (0: never)")
        need(isinstance(self.eval_prefs, int) and self.eval_prefs >= 1, "eval_prefs", "must be >= 1")
        need(self.ref_point is None or all(math.isfinite(x) for x in self.ref_point), "ref_point",
             "must be finite numbers")
        need(isinstance(self.checkpoint_every, int) and self.checkpoint_every >= 0, "checkpoint_every",
             "must be >= 0 (0: only at the end)")

    # ------------------------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain, JSON-safe dict of every field, plus the derived ``algo``."""
        d = dataclasses.asdict(self)
        d["hidden_sizes"] = list(self.hidden_sizes)
        d["disc_hidden"] = list(self.disc_hidden)
        d["ref_point"] = None if self.ref_point is None else list(self.ref_point)
        d["algo"] = self.algo
        return d

    @classmethod
    def field_names(cls) -> list[str]:
        """Names of all settable fields."""
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Config:
        """Build from a dict (a saved config or overrides). ``algo`` sets the exploration switches."""
        data = dict(data)
        algo = data.pop("algo", None)
        names = cls.field_names()
        for key in data:
            if key not in names:
                raise unknown_key_error(key)
        if algo is not None:
            return cls.for_algo(algo, **data)
        types = {f.name: f.type for f in dataclasses.fields(cls)}
        for key, value in data.items():
            # ints given as floats ("20000.0") and bools given as ints are user slips: coerce where lossless.
            if types[key] in ("int", "int | None") and isinstance(value, float) and value.is_integer():
                data[key] = int(value)
        return cls(**data)

    def save(self, path: str | Path) -> None:
        """Write the resolved config as JSON.

        Raises:
            ConfigError: if the file cannot be written (missing permission, a file where a folder should be).
        """
        try:
            Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")
        except OSError as exc:
            raise ConfigError(f"config file '{path}' could not be written: {exc.strerror or exc}") from None

    @classmethod
    def load(cls, path: str | Path) -> Config:
        """Read a config from JSON or YAML."""
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"config file '{path}' does not exist")
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
            raise ConfigError(f"config file '{path}' could not be read: {reason}") from None
        try:
            if path.suffix in (".yaml", ".yml"):
                import yaml

                data = yaml.safe_load(text) or {}
            else:
                data = json.loads(text)
        except Exception as exc:  # noqa: BLE001 - any parse failure is the user's file
            raise ConfigError(f"config file '{path}' could not be parsed: {_parse_problem(exc)}") from None
        if not isinstance(data, dict):
            raise ConfigError(f"config file '{path}' must hold a mapping of settings")
        return cls.from_dict(data)


def unknown_key_error(key: str) -> ConfigError:
    """The error for a key that is not a :class:`Config` field, with the closest field name when one is close."""
    names = Config.field_names()
    hint = suggest(key, names) or "; valid keys are the fields of mope.Config, e.g. gamma, n_omega, sigma_omega"
    return ConfigError(f"unknown config key '{key}'{hint}")


def _parse_problem(exc: Exception) -> str:
    """A short description of a JSON or YAML parse error with its line and column."""
    problem = getattr(exc, "problem", None)  # yaml.MarkedYAMLError
    mark = getattr(exc, "problem_mark", None)
    if problem and mark is not None:
        return f"{problem} at line {mark.line + 1}, column {mark.column + 1}"
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


_dataclass_init = Config.__init__


@functools.wraps(_dataclass_init)
def _checked_init(self: Config, *args: Any, **kwargs: Any) -> None:
    # Config(sigma_omgea=0.1) would otherwise fail with a TypeError from the generated __init__.
    for key in kwargs:
        if key not in _FIELD_NAMES:
            raise unknown_key_error(key)
    _dataclass_init(self, *args, **kwargs)


_FIELD_NAMES = frozenset(Config.field_names())
Config.__init__ = _checked_init  # type: ignore[method-assign]
