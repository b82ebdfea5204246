"""Demonstrations on Deep-Sea-Treasure with L^B's weight 4 (today's default): the lift of the DQfD learning test
(tests/test_learning_from_demonstrations.py), per seed, with demo_loss_weight 1 and 4.

usage: python scripts/demos_lb_weight.py STEPS SEEDS   (e.g. 3000 0,1,2,3,4,5); one JSON line per seed:
(optimal share, CR, seconds) of each arm. Output of 3000 0,1,2,3,4,5: docs/results/lb-loss/demos-w4.jsonl.
"""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from demos_test_probe import demonstrations_and_evaluator, train_arm  # noqa: E402


def main(steps: int, seeds: list[int]) -> None:
    path, ev = demonstrations_and_evaluator()
    arms = {"plain": {"demos": ""}, "demo1": {"demos": str(path)},
            "demo4": {"demos": str(path), "demo_loss_weight": 4.0}}
    for seed in seeds:
        row: dict = {"seed": seed}
        for name, kw in arms.items():
            share, cr, secs = train_arm(ev, seed, steps, **kw)
            row[name] = (round(share, 3), round(cr, 3), round(secs))
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main(int(sys.argv[1]), [int(s) for s in sys.argv[2].split(",")])
