"""PPO baseline, GIF rollouts and ``reproduce_confrontation`` (tiny budgets)."""

from __future__ import annotations

import json

import imageio.v3 as iio
import mo_gymnasium as mo_gym
import numpy as np
import pytest

import mope.envs.confrontation as C
from mope.errors import ConfigError, MopeError
from mope.evaluation.video import VideoError, record_video
from mope.paper.confrontation import (
    acceptance_scores,
    reproduce_confrontation,
    speed_class,
    strategy_diversity,
    summarize,
)
from mope.paper.ppo import Episodes, play_episodes, train_ppo


def make() -> C.RobotConfrontationDiscreteEnv:
    return mo_gym.make(C.DISCRETE_ID).unwrapped


def test_play_episodes_matches_sequential_play() -> None:
    def policy(obs: np.ndarray, idx: np.ndarray) -> np.ndarray:
        return (idx * 3 + 1) % 15

    eps = play_episodes(policy, make, 3, [4, 5, 6], max_steps=40, gamma=0.9, record=True)
    for i, seed in enumerate([4, 5, 6]):
        env = make()
        env.reset(seed=seed)
        total, disc, g, steps = np.zeros(2), np.zeros(2), 1.0, 0
        for _ in range(40):
            _, r, term, _, info = env.step((i * 3 + 1) % 15)
            steps += 1
            total += r
            disc += g * r
            g *= 0.9
            if term:
                break
        assert np.allclose(eps.returns[i], total) and np.allclose(eps.discounted[i], disc)
        assert eps.lengths[i] == steps and eps.outcomes[i] == info["outcome"]
        assert eps.histories[i].shape == (steps + 1, 2, 4)
    with pytest.raises(ConfigError, match="2 seeds for 3 episodes"):
        play_episodes(policy, make, 3, [1, 2], 5)


def test_strategy_diversity_counts_outcome_and_speed_types() -> None:
    assert list(speed_class(np.array([0.0, 0.2, 0.3, 0.5]), 0.5)) == [0, 1, 1, 2]
    outcomes = [["red_win", "red_win", "blue_win"], ["red_win"] * 3, ["blue_win"] * 3, ["running"] * 3]
    d = strategy_diversity(outcomes, np.array([0.45, 0.45, 0.45, 0.05]), 0.5)
    # (red_win, fast) twice, (blue_win, fast), (running, slow): 3 strategies, entropy of (1/2, 1/4, 1/4) = 1.5
    assert d == {"strategies": 3, "entropy_bits": pytest.approx(1.5)}


def test_acceptance_scores_pool_the_exits_at_low_catch_weights_and_keep_the_worst() -> None:
    outs = {0.0: 0.0, 0.1: 0.0, 0.2: 0.02, 0.3: 0.04, 0.4: 0.12, 0.5: 0.02}
    rates = {w: {"win": w / 2, "out": o} for w, o in outs.items()}
    rates.update({w: {"win": w / 2, "out": 0.5} for w in (0.7, 0.8, 0.9, 1.0)})
    s = acceptance_scores(np.array([1.0, 2.0]), np.array([0.5, 2.5]), rates)
    assert s["out_lo"] == pytest.approx(0.2 / 6) and s["out_lo_max"] == pytest.approx(0.12)
    assert s["win_hi"] == pytest.approx(0.45) and s["win_0.7"] == pytest.approx(0.35)
    assert (s["eu"], s["eu_envelope"], s["eu_gap"]) == pytest.approx((1.5, 1.5, 0.0))


def test_summarize_rates_and_hypervolume() -> None:
    prefs = np.array([[0.0, 1.0], [1.0, 0.0]])
    eps = Episodes(returns=np.array([[10.0, 2.0], [-10.0, 4.0], [-20.0, -10.0], [-30.0, 6.0]]),
                   discounted=np.zeros((4, 2)), lengths=np.array([20, 40, 10, 150]),
                   outcomes=["red_win", "blue_win", "red_out", "running"])
    s = summarize(prefs, eps, 2, np.array([-100.0, -20.0]), dt=0.2, v_max=0.5)
    assert np.allclose(s["points"], [[0.0, 3.0], [-25.0, -2.0]])
    assert (s["win"], s["loss"], s["out"], s["timeout"]) == (0.25, 0.25, 0.25, 0.25)
    assert s["hv"] == pytest.approx(100 * 23)  # the first point dominates the second
    assert s["r_catch"] == pytest.approx(-12.5)


def test_train_ppo_learns_a_policy_of_the_right_shape() -> None:
    model = train_ppo([0.5, 0.5], 128, seed=0)
    obs, _ = mo_gym.make(C.CONTINUOUS_ID).reset(seed=0)
    act = model.predict(obs, deterministic=True)[0]
    assert act.shape == (2,)
    with pytest.raises(MopeError, match="sums to"):
        train_ppo([0.5, 0.6], 128)


def test_ppo_trains_on_actions_rescaled_to_the_unit_box_with_no_checker_warning() -> None:
    import warnings

    from stable_baselines3.common.env_checker import check_env

    from mope.paper.ppo import make_scalarized_env, rescale_to_box

    env = make_scalarized_env(C.CONTINUOUS_ID, np.array([0.5, 0.5]))
    assert env.action_space.low.tolist() == [-1, -1] and env.action_space.high.tolist() == [1, 1]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, warn=True)
    assert not [w for w in caught if "action" in str(w.message).lower()], [str(w.message) for w in caught]
    box = mo_gym.make(C.CONTINUOUS_ID).action_space
    np.testing.assert_allclose(rescale_to_box(np.array([[-1.0, 1.0], [0.0, 0.5]]), box), [[-0.2, 0.8], [0.0, 0.4]],
                               atol=1e-6)


def test_reference_policies_reproduce_their_outcome_rates() -> None:
    from collections import Counter

    from mope.envs.confrontation_batch import play_reference

    seeds = list(range(200))
    rates = {}
    for name in ("scripted pursuer", "leave the arena", "pure pursuit", "random"):
        _, disc, outcomes = play_reference(name, seeds)
        rates[name] = {k: v / len(seeds) for k, v in Counter(outcomes).items()}
        rates[name]["disc"] = disc.mean(axis=0)
    assert 0.5 <= rates["scripted pursuer"].get("red_win", 0) <= 0.7  # measured 0.59 (seeds 0-99)
    assert rates["scripted pursuer"].get("red_out", 0) == 0
    assert rates["leave the arena"].get("red_out", 0) >= 0.95  # measured 0.985
    assert rates["pure pursuit"].get("running", 0) >= 0.9 and rates["pure pursuit"].get("red_win", 0) == 0
    assert rates["random"].get("blue_win", 0) >= 0.8
    assert rates["leave the arena"]["disc"][0] > rates["pure pursuit"]["disc"][0]  # the trap: leaving pays on catch


def test_record_video_writes_every_frame(tmp_path) -> None:
    info = record_video(lambda obs: 7, C.DISCRETE_ID, None, tmp_path / "game.gif", seed=3, max_steps=6)
    frames = iio.imread(tmp_path / "game.gif")
    assert info["frames"] == 7 and len(frames) == 7 and frames.shape[-1] in (3, 4)
    assert info["return"].shape == (2,) and info["outcome"] in C.OUTCOMES


def test_record_video_on_deep_sea_treasure_and_errors(tmp_path) -> None:
    info = record_video(lambda obs: 1, "deep-sea-treasure-v0", [0.5, 0.5], tmp_path / "dst.gif", max_steps=3)
    assert info["frames"] == 2 and info["return"][0] == pytest.approx(0.7)  # one step down: the first treasure
    with pytest.raises(VideoError, match="cannot render rgb_array"):
        record_video(lambda obs: 0, "fishwood-v0", None, tmp_path / "f.gif", max_steps=2)
    with pytest.raises(VideoError, match="did you mean"):
        record_video(lambda obs: 0, "deep-sea-treasur-v0", None, tmp_path / "f.gif")
    with pytest.raises(VideoError, match=r"\.gif"):
        record_video(lambda obs: 0, C.DISCRETE_ID, None, tmp_path / "f.mp4")


def test_reproduce_rejects_bad_arguments(tmp_path) -> None:
    with pytest.raises(ConfigError, match="ppo_budget"):
        reproduce_confrontation(tmp_path, ppo_budget="half")
    with pytest.raises(ConfigError, match="episodes=0"):
        reproduce_confrontation(tmp_path, episodes=0)
    with pytest.raises(ConfigError, match="per PPO policy"):
        reproduce_confrontation(tmp_path, steps=100, ppo_budget="shared")
    with pytest.raises(ConfigError, match="'3-1': the range ends before it starts"):
        reproduce_confrontation(tmp_path, seeds="3-1")


def test_confrontation_seeds_take_a_count_a_range_or_a_list() -> None:
    from mope.paper.confrontation import check_confrontation_args, confrontation_jobs

    for given, want in ((2, [0, 1]), ("4-5", [4, 5]), ("7,2", [7, 2])):
        seeds, ppo_steps = check_confrontation_args(given, 1000, 2, 3, 2, 1, "each")
        assert seeds == want and ppo_steps == 1000
    names = [j.name for j in confrontation_jobs([5], 1000, 2, 1000, 3, "cpu", {})]
    assert names == ["eql-s5", "mope-nodemo-s5", "mope-s5", "ppo-s5-pref00", "ppo-s5-pref01"]
    configs = {j.name: j.payload for j in confrontation_jobs([5], 1000, 2, 1000, 3, "cpu", {})}
    # every agent starts from the game's defaults; only "mope" keeps their demonstrations
    assert {configs[n]["n_envs"] for n in ("eql-s5", "mope-nodemo-s5", "mope-s5")} == {4}
    assert (configs["mope-s5"]["demos"], configs["mope-nodemo-s5"]["demos"], configs["eql-s5"]["demos"]) == \
        ("scripted", "", "")
    assert not configs["eql-s5"]["experience_exploration"] and configs["mope-nodemo-s5"]["experience_exploration"]


@pytest.mark.slow
def test_reproduce_confrontation_tiny(tmp_path) -> None:
    r = reproduce_confrontation(tmp_path, steps=250, ppo_prefs=2, eval_prefs=3, episodes=2, workers=1,
                                progress=False, n_omega=4, learning_starts=100, demo_episodes=2,
                                demo_pretrain_steps=20)
    for name in ("fig5_front.png", "fig6_trajectories.png", "table.md", "results.json"):
        assert (tmp_path / name).is_file()
    res = json.loads((tmp_path / "results.json").read_text())["results"]
    assert set(res) == {"ppo", "eql", "mope-nodemo", "mope", "scripted pursuer", "leave the arena", "pure pursuit",
                        "random", "reference_front_hv"}
    assert res["leave the arena"]["out"]["mean"] > 0.9  # 2 initial states: too few for the pursuer's win rate
    assert "| reference: scripted pursuer |" in r["table"] and res["reference_front_hv"] > 0
    for m, n_sol in (("ppo", 2), ("eql", 3), ("mope-nodemo", 3), ("mope", 3)):
        rates = sum(res[m][k]["mean"] for k in ("win", "loss", "out", "blue_out", "timeout"))
        assert rates == pytest.approx(1.0) and res[m]["solutions"] == n_sol
        # the acceptance scores: utilities against the same references' envelope, shares in [0, 1]
        assert res[m]["eu_envelope"]["mean"] == pytest.approx(res["scripted pursuer"]["eu_envelope"]["mean"])
        assert res[m]["eu_gap"]["mean"] == pytest.approx(res[m]["eu"]["mean"] - res[m]["eu_envelope"]["mean"])
        assert 0 <= res[m]["win_hi"]["mean"] <= 1 and 0 <= res[m]["out_lo_max"]["mean"] <= 1
    # the envelope is the best reference at each preference, so no reference is above it
    for name in ("scripted pursuer", "leave the arena", "pure pursuit", "random"):
        assert res[name]["eu_gap"]["mean"] <= 1e-9
    assert "MoPE alone (the paper's method)" in r["table"] and "EU - references' envelope" in r["table"]
    assert "| mope | 1 x 3 |" in r["table"]
    # a second call reuses every finished run
    again = reproduce_confrontation(tmp_path, steps=250, ppo_prefs=2, eval_prefs=3, episodes=2, workers=1,
                                    progress=False, n_omega=4, learning_starts=100, demo_episodes=2,
                                    demo_pretrain_steps=20)
    assert again["train_wall_s"] < r["train_wall_s"]


def test_a_saved_ppo_policy_of_another_budget_is_not_reused(tmp_path):
    import json

    from mope.experiments.jobs import run_job

    meta = {"pref": [1.0, 0.0], "steps": 64, "seed": 0, "env_id": "mope/RobotConfrontation-v0"}
    folder = tmp_path / "ppo-s0-pref00"
    folder.mkdir()
    (folder / "policy.zip").write_bytes(b"not trained here")
    (folder / "summary.json").write_text(json.dumps({"meta": meta, "final": {"wall_s": 1.0}}))
    rec = run_job("ppo-s0-pref00", "ppo", {**meta, "device": "cpu"}, str(folder))
    assert rec["status"] == "finished" and rec["action"] == "skipped"  # same budget: reused, not retrained
    assert (folder / "policy.zip").read_bytes() == b"not trained here"
    rec = run_job("ppo-s0-pref00", "ppo", {**meta, "steps": 128, "device": "cpu"}, str(folder))
    assert rec["status"] == "failed" and "steps" in rec["error"]
