"""The arms of the demonstrations learning test (tests/test_learning_from_demonstrations.py,
``test_a_short_training_with_demonstrations_beats_one_without``) per seed, with any settings: a budget for the test.

usage: python scripts/demos_test_probe.py STEPS SEEDS [SETTINGS] [DEMO_SETTINGS]
  SETTINGS (both arms) and DEMO_SETTINGS (the demonstrations arm only) are Python dicts, e.g.
  python scripts/demos_test_probe.py 1500 0,1,2,3,4,5 "{}" "{'demo_pretrain_steps': 500}"
One line per seed and arm: optimal share, CR and seconds. Both arms use L^B's weight 1, as the test does.
Outputs: docs/results/demos-test/README.md.
"""

import ast
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from test_learning_from_demonstrations import treasure_demonstrations  # noqa: E402

from mope import MoPE  # noqa: E402
from mope.agent.demonstrations import save_demonstrations  # noqa: E402
from mope.envs import make_env  # noqa: E402
from mope.evaluation.evaluator import Evaluator  # noqa: E402


def demonstrations_and_evaluator() -> tuple[Path, Evaluator]:
    """The learning test's demonstrations (saved to a temporary file) and a Deep-Sea-Treasure evaluator."""
    path = save_demonstrations(Path(tempfile.mkdtemp()) / "treasures.npz", treasure_demonstrations())
    return path, Evaluator.from_config(make_env("deep-sea-treasure-v0"), MoPE("deep-sea-treasure-v0").config)


def train_arm(ev: Evaluator, seed: int, steps: int, **settings: object) -> tuple[float, float, float]:
    """Train one arm for ``steps`` and return its (optimal share, CR, seconds)."""
    t = time.time()
    agent = MoPE("deep-sea-treasure-v0", seed=seed, **settings)
    agent.train(steps)
    r = ev.evaluate(agent)[0]
    return r["optimal_share"], r["cr"], time.time() - t


def main(steps: int, seeds: list[int], settings: dict, demo_settings: dict) -> None:
    torch.set_num_threads(1)
    path, ev = demonstrations_and_evaluator()
    for seed in seeds:
        for demos in (str(path), ""):
            share, cr, secs = train_arm(ev, seed, steps, demos=demos, lb_weight=1.0, **settings,
                                        **(demo_settings if demos else {}))
            print(seed, "demos" if demos else "none ", f"share {share:.3f} cr {cr:.3f}  {secs:.0f}s", flush=True)


if __name__ == "__main__":
    extra = [ast.literal_eval(a) for a in sys.argv[3:5]]
    main(int(sys.argv[1]), [int(s) for s in sys.argv[2].split(",")], *(extra + [{}, {}])[:2])
