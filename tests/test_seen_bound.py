"""The targets' upper clamp from the returns seen (``seen_bound_margin``): known values, where the returns come
from, and that a clamped target never exceeds it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mope import MoPE
from mope.agent.base import seen_upper_bound, suffix_returns
from mope.config import Config
from mope.errors import ConfigError

SMALL = {"total_steps": 600, "learning_starts": 50, "n_omega": 8, "hidden_sizes": [32, 32], "seed": 2}


def test_suffix_returns_by_hand():
    r = np.array([[1.0, 0.0], [0.0, 1.0], [2.0, 2.0]])
    # G_2 = (2, 2); G_1 = (0, 1) + 0.5 (2, 2) = (1, 2); G_0 = (1, 0) + 0.5 (1, 2) = (1.5, 1)
    np.testing.assert_allclose(suffix_returns(r, 0.5), [[1.5, 1.0], [1.0, 2.0], [2.0, 2.0]])
    long = np.ones((1000, 1))  # a 1,000-step episode at gamma 0.99 (minecart's): no under- or overflow
    np.testing.assert_allclose(suffix_returns(long, 0.99)[0, 0], (1 - 0.99 ** 1000) / 0.01)


def test_seen_upper_bound_is_the_lower_of_the_space_and_the_seen_range():
    space = np.array([150.0, 0.0])
    low, high = np.array([0.0, -7.0]), np.array([1.5, -0.02])
    # ore: 1.5 + 0.1 * 1.5 = 1.65 < 150; fuel: -0.02 + 0.1 * 6.98 = 0.678 > 0, so the space's 0 stays
    np.testing.assert_allclose(seen_upper_bound(space, low, high, 0.1), [1.65, 0.0])
    np.testing.assert_allclose(seen_upper_bound(space, low, high, 0.0), [1.5, -0.02])


def test_the_clamp_follows_the_returns_of_ended_episodes():
    a = MoPE("deep-sea-treasure-v0", Config.for_algo("mope", seen_bound_margin=0.0, **SMALL))
    np.testing.assert_allclose(a._q_high_t.numpy(), a.q_high)  # nothing seen yet: the reward space's bound
    a.train(600)
    assert a.episodes > 0 and a.seen_returns is not None
    low, high = a.seen_returns
    # DST's treasure returns are the treasures found, discounted; the time objective's best is -1 (the last step)
    assert 0.0 <= high[0] <= 23.7 and high[1] == pytest.approx(-1.0)
    assert low[1] < -1.0
    np.testing.assert_allclose(a._q_high_t.numpy(), np.minimum(a.q_high, high), rtol=1e-6)
    batch = a.buffer.sample(64, np.random.default_rng(0), 0.4)
    w = torch.full((64, 4, 2), 0.5)
    y = a._envelope_target(batch, w, w[:, 0])
    assert bool((y <= a._q_high_t + 1e-6).all())


def test_on_by_default_and_off_the_clamp_is_the_reward_spaces():
    assert Config().seen_bound_margin == 0.1  # the default since 2026-12-07 (issue 33)
    a = MoPE("deep-sea-treasure-v0", Config.for_algo("mope", seen_bound_margin=None, **SMALL))
    a.train(300)
    assert a.seen_returns is None and a.episodes > 0  # episodes ended, and none tightened the clamp
    np.testing.assert_allclose(a._q_high_t.numpy(), a.q_high)


def test_demonstrations_count_as_seen():
    a = MoPE("mope/RobotConfrontationDiscrete-v0",
             Config.for_algo("mope", env_id="mope/RobotConfrontationDiscrete-v0", demos="scripted",
                             demo_episodes=5, seen_bound_margin=0.1, buffer_size=5000, **SMALL))
    assert a.seen_returns is not None  # before any training step
    assert a.seen_returns[1, 0] <= 10.0 and a._q_high_t[0] < 1000.0


@pytest.mark.parametrize("bad", [-0.1, float("nan"), "x"])
def test_bad_margin_is_a_config_error(bad):
    with pytest.raises(ConfigError, match="seen_bound_margin"):
        Config(seen_bound_margin=bad)
