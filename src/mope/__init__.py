"""mope: Multi-objective RL with Preference Exploration.

One preference-conditioned agent that acts well under any trade-off between objectives: Envelope Q-learning
(Yang et al. 2019) with the experience exploration and preference exploration of MoPE (Xi and Guo).

Public API::

    from mope import MoPE, EQL, Config, Evaluator, solutions
    agent = MoPE("deep-sea-treasure-v0", seed=0)
    agent.train(20_000, eval_env=mope.make_env("deep-sea-treasure-v0"), progress=True)
"""

from mope.agent import EQL, MoPE, TrainingDivergedError, make_agent
from mope.config import ALGOS, Config
from mope.envs import make_env
from mope.errors import CheckpointError, ConfigError, MopeError, PreferenceError
from mope.evaluation import Evaluator, Solutions, solutions

__all__ = [
    "ALGOS",
    "EQL",
    "CheckpointError",
    "Config",
    "ConfigError",
    "Evaluator",
    "MoPE",
    "MopeError",
    "PreferenceError",
    "Solutions",
    "TrainingDivergedError",
    "make_agent",
    "make_env",
    "solutions",
]
