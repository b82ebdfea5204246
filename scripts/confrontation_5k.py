"""The confrontation slow test's measurement with config overrides: 5k steps of MoPE (seed 0) on the discrete game,
then blue's win share against it and red's discounted catch return, beside random red's.

Usage::

    .venv/bin/python scripts/confrontation_5k.py '{"n_step": 5}'

(`tests/test_confrontation.py::test_a_short_training_beats_random_red` asserts, with the defaults, a loss share
at least 0.15 below random red's 0.86 and a catch return at least 0.5 above random red's.)
"""

from __future__ import annotations

import json
import sys

from mope.agent.agent import MoPE
from mope.envs import confrontation as C
from mope.envs import make_env
from mope.envs.confrontation_batch import play_reference
from mope.evaluation.evaluator import Evaluator

overrides = json.loads(sys.argv[1]) if len(sys.argv) > 1 else {}
agent = MoPE(C.DISCRETE_ID, seed=0, total_steps=5000, **overrides)
agent.train(5000)
ev = Evaluator(make_env(C.DISCRETE_ID), C.DISCRETE_ID, 0.99, n_prefs=50, seed=0, max_steps=150,
               ref_point=C.reference_point(0.99, 150))
res, sols = ev.evaluate(agent)
_, disc, outcomes = play_reference("random", list(range(200)))
print(json.dumps({"overrides": overrides, "loss_share": res["loss_share"],
                  "random_loss_share": outcomes.count("blue_win") / len(outcomes),
                  "catch_return": float(sols.discounted[:, 0].mean()),
                  "random_catch_return": float(disc[:, 0].mean())}))
