"""Demonstrations on Deep-Sea-Treasure with L^B's weight 4 (today's default): the lift of the DQfD learning test
(tests/test_learning_from_demonstrations.py), per seed, with demo_loss_weight 1 and 4.

usage: python scripts/demos_lb_weight.py STEPS SEEDS   (e.g. 3000 0,1,2,3,4,5); one JSON line per seed:
(optimal share, CR, seconds) of each arm. Output of 3000 0,1,2,3,4,5: docs/results/lb-loss/demos-w4.jsonl.
"""

import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_learning_from_demonstrations import treasure_demonstrations  # noqa: E402

from mope import MoPE  # noqa: E402
from mope.agent.demonstrations import save_demonstrations  # noqa: E402
from mope.envs import make_env  # noqa: E402
from mope.evaluation.evaluator import Evaluator  # noqa: E402


def main(steps: int, seeds: list[int]) -> None:
    path = save_demonstrations(Path(tempfile.mkdtemp()) / "treasures.npz", treasure_demonstrations())
    ev = Evaluator.from_config(make_env("deep-sea-treasure-v0"), MoPE("deep-sea-treasure-v0").config)
    arms = {"plain": {"demos": ""}, "demo1": {"demos": str(path)},
            "demo4": {"demos": str(path), "demo_loss_weight": 4.0}}
    for seed in seeds:
        row: dict = {"seed": seed}
        for name, kw in arms.items():
            t = time.time()
            agent = MoPE("deep-sea-treasure-v0", seed=seed, **kw)
            agent.train(steps)
            r = ev.evaluate(agent)[0]
            row[name] = (round(r["optimal_share"], 3), round(r["cr"], 3), round(time.time() - t))
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), [int(s) for s in sys.argv[2].split(",")])
