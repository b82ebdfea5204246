"""Tests of mope.config: paper defaults, validation messages, algorithm switches and file round trips."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from mope.config import ALGOS, Config
from mope.errors import ConfigError, MopeError


# ------------------------------------------------------------------------------------------- defaults
def test_paper_preset_matches_the_paper() -> None:
    c = Config.from_dict({"preset": "paper"})
    assert c.n_omega == 64  # "we sample 64 preferences"
    assert c.sigma_omega == 0.04  # "sigma_omega = 0.04"
    assert c.n_intervals == 10  # "divided the preference space into 10 parts"
    assert c.hidden_sizes == (64, 128, 128, 64)  # "four fully connected hidden layers {64, 128, 128, 64}"
    assert c.pe_count_offset == 0.01  # p(w) ~ (N_i + 0.01)^(-1/2)
    assert c.gamma == 0.99
    assert c.run.eval_prefs == 2000
    assert c.lb_weight == 1.0
    assert c.experience_exploration and c.preference_exploration
    assert c.algo == "mope"
    assert c.env_id == "deep-sea-treasure-v0"


def test_sequences_become_tuples() -> None:
    c = Config(hidden_sizes=[32, 32], disc_hidden=[16], ref_point=[0, -25])
    assert c.hidden_sizes == (32, 32)
    assert c.disc_hidden == (16,)
    assert c.run.ref_point == (0.0, -25.0)
    assert all(isinstance(x, float) for x in c.run.ref_point)


# ------------------------------------------------------------------------------------------- dict round trip
def test_to_dict_from_dict_round_trip() -> None:
    c = Config(seed=3, total_steps=1234, gamma=0.9, hidden_sizes=(8, 16), ref_point=(0.0, -25.0), n_omega=8,
               sigma_omega=0.1, experience_exploration=False, max_episode_steps=50)
    d = c.to_dict()
    assert d["algo"] == "pe"
    assert d["hidden_sizes"] == [8, 16] and d["ref_point"] == [0.0, -25.0] and d["disc_hidden"] == [64, 64]
    assert json.loads(json.dumps(d)) == d  # JSON-safe
    back = Config.from_dict(d)
    assert back == c
    assert back.to_dict() == d


def test_from_dict_coerces_integral_floats() -> None:
    c = Config.from_dict({"total_steps": 20000.0, "batch_size": 16.0})
    assert c.total_steps == 20000 and isinstance(c.total_steps, int)
    assert c.batch_size == 16 and isinstance(c.batch_size, int)
    with pytest.raises(ConfigError, match=r"total_steps=20000\.5 is not an integer"):
        Config.from_dict({"total_steps": 20000.5})


def test_replace_validates() -> None:
    c = Config()
    d = c.replace(gamma=0.5)
    assert d.gamma == 0.5 and c.gamma == 0.99
    with pytest.raises(ConfigError, match="gamma"):
        c.replace(gamma=2.0)


# ------------------------------------------------------------------------------------------- algorithms
@pytest.mark.parametrize(
    ("algo", "ee", "pe"), [("eql", False, False), ("ee", True, False), ("pe", False, True), ("mope", True, True)]
)
def test_for_algo_sets_switches_and_algo_derives_back(algo: str, ee: bool, pe: bool) -> None:
    c = Config.for_algo(algo, seed=1)
    assert (c.experience_exploration, c.preference_exploration) == (ee, pe)
    assert c.algo == algo
    assert c.seed == 1
    assert ALGOS[algo] == (ee, pe)
    # the derived name survives a round trip through a dict
    assert Config.from_dict(c.to_dict()).algo == algo
    assert Config.from_dict({"algo": algo}).algo == algo
    assert Config(experience_exploration=ee, preference_exploration=pe).algo == algo


def test_for_algo_unknown_suggests() -> None:
    with pytest.raises(ConfigError, match=r"unknown algorithm 'mop'.*did you mean 'mope'"):
        Config.for_algo("mop")


def test_for_algo_contradiction() -> None:
    with pytest.raises(ConfigError, match="contradicts"):
        Config.for_algo("eql", experience_exploration=True)
    with pytest.raises(ConfigError, match="contradicts"):
        Config.from_dict({"algo": "mope", "preference_exploration": False})


# ------------------------------------------------------------------------------------------- validation
@pytest.mark.parametrize(
    ("changes", "field", "value"),
    [
        ({"sigma_omega": 0.0}, "sigma_omega", "0.0"),
        ({"sigma_omega": -0.04}, "sigma_omega", "-0.04"),
        ({"n_omega": 0}, "n_omega", "0"),
        ({"mi_alpha": -0.1}, "mi_alpha", "-0.1"),
        ({"n_intervals": 0}, "n_intervals", "0"),
        ({"n_critics": 0}, "n_critics", "0"),
        ({"gamma": 0.0}, "gamma", "0.0"),
        ({"gamma": 1.5}, "gamma", "1.5"),
        ({"gamma": float("nan")}, "gamma", "nan"),
        ({"total_steps": 0}, "total_steps", "0"),
        ({"learning_rate": float("nan")}, "learning_rate", "nan"),
        ({"learning_rate": 0.0}, "learning_rate", "0.0"),
        ({"learning_rate": float("inf")}, "learning_rate", "inf"),
        ({"batch_size": 64, "buffer_size": 32}, "buffer_size", "32"),
        ({"per_eps": 0.0}, "per_eps", "0.0"),
        ({"per_beta_start": 1.5}, "per_beta_start", "1.5"),
        ({"epsilon_start": -0.1}, "epsilon_start", "-0.1"),
        ({"pe_count_offset": 0.0}, "pe_count_offset", "0.0"),
        ({"eval_prefs": 0}, "eval_prefs", "0"),
        ({"hidden_sizes": ()}, "hidden_sizes", "()"),
        ({"hidden_sizes": (64, 0)}, "hidden_sizes", "(64, 0)"),
        ({"envelope_prefs": "all"}, "envelope_prefs", "'all'"),
        ({"device": "tpu"}, "device", "'tpu'"),
        ({"seed": -1}, "seed", "-1"),
        ({"env_id": ""}, "env_id", "''"),
        ({"max_grad_norm": 0.0}, "max_grad_norm", "0.0"),
        ({"return_mix": 1.5}, "return_mix", "1.5"),
        ({"return_mix": float("nan")}, "return_mix", "nan"),
        ({"return_window": 0}, "return_window", "0"),
        ({"ref_point": (0.0, float("nan"))}, "ref_point", "nan"),
        ({"consistent_bellman": True, "n_step": 3}, "consistent_bellman", "True"),
        ({"target_tau_end": 0.0}, "target_tau_end", "0.0"),
        ({"target_tau_end": float("nan")}, "target_tau_end", "nan"),
        ({"target_tau_anneal_from": 1.0}, "target_tau_anneal_from", "1.0"),
        ({"consistent_bellman": True, "q_head": "conditioned"}, "consistent_bellman", "True"),
        ({"lb_loss": "huber"}, "lb_loss", "'huber'"),
    ],
)
def test_out_of_range_raises_config_error_naming_field_and_value(changes: dict, field: str, value: str) -> None:
    with pytest.raises(ConfigError) as info:
        Config(**changes)
    msg = str(info.value)
    assert msg.startswith(f"{field}=")
    assert value in msg
    assert "out of range" in msg
    assert "\n" not in msg


def test_batch_size_larger_than_buffer_message() -> None:
    with pytest.raises(ConfigError, match=r"buffer_size=16 is out of range: must be >= batch_size \(128\)"):
        Config(buffer_size=16)


def test_config_error_is_mope_error_and_value_error() -> None:
    with pytest.raises(MopeError):
        Config(gamma=0.0)
    with pytest.raises(ValueError):
        Config(gamma=0.0)


def test_boundary_values_accepted() -> None:
    c = Config(gamma=1.0, n_omega=1, n_intervals=1, mi_alpha=0.0, total_steps=1, batch_size=32, buffer_size=32,
               epsilon_start=0.0, epsilon_end=1.0, per_beta_start=1.0, max_grad_norm=None, eval_every=0)
    assert c.gamma == 1.0 and c.n_omega == 1 and c.buffer_size == c.batch_size
    assert math.isfinite(c.sigma_omega)


def test_from_dict_wrong_type_for_int_field() -> None:
    with pytest.raises(ConfigError, match="n_omega='64' is not an integer"):
        Config.from_dict({"n_omega": "64"})


@pytest.mark.parametrize(
    ("key", "suggestion"),
    [("sigma_omgea", "sigma_omega"), ("nomega", "n_omega"), ("learning_rat", "learning_rate"), ("gama", "gamma")],
)
def test_unknown_key_suggests_closest(key: str, suggestion: str) -> None:
    with pytest.raises(ConfigError) as info:
        Config.from_dict({key: 1})
    assert f"unknown config key '{key}'" in str(info.value)
    assert f"did you mean '{suggestion}'" in str(info.value)


def test_unknown_key_without_close_match() -> None:
    with pytest.raises(ConfigError) as info:
        Config.from_dict({"zzzzzzzz": 1})
    assert "unknown config key 'zzzzzzzz'" in str(info.value)
    assert "did you mean" not in str(info.value)


# ------------------------------------------------------------------------------------------- files
def test_load_yaml(tmp_path: Path) -> None:
    p = tmp_path / "run.yaml"
    p.write_text("algo: ee\nseed: 4\nsigma_omega: 0.08\nhidden_sizes: [32, 32]\ntotal_steps: 500\n")
    c = Config.load(p)
    assert c.algo == "ee" and c.seed == 4 and c.sigma_omega == 0.08
    assert c.hidden_sizes == (32, 32) and c.total_steps == 500


def test_yaml_reads_exponents_without_a_dot_as_numbers(tmp_path: Path) -> None:
    """PyYAML (YAML 1.1) reads ``3e-4`` as a string, so a config file with ``learning_rate: 3e-4`` used to stop
    with "is not a number"; mope reads YAML 1.2's floats. A quoted value stays a string."""
    p = tmp_path / "run.yaml"
    p.write_text("learning_rate: 3e-4\nlearning_rate_end: 3E-05\nsigma_omega: 4e-2\ntotal_steps: 1_000\n")
    c = Config.load(p)
    assert c.learning_rate == 3e-4 and c.learning_rate_end == 3e-5 and c.sigma_omega == 0.04
    assert c.total_steps == 1000 and isinstance(c.total_steps, int)
    p.write_text('learning_rate: "3e-4"\n')
    with pytest.raises(ConfigError, match="learning_rate='3e-4' is not a number"):
        Config.load(p)


def test_load_yml_suffix_and_empty_yaml(tmp_path: Path) -> None:
    p = tmp_path / "run.yml"
    p.write_text("gamma: 0.95\n")
    assert Config.load(p).gamma == 0.95
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert Config.load(empty) == Config()


def test_save_and_load_json(tmp_path: Path) -> None:
    c = Config.for_algo("eql", seed=9, n_omega=16, ref_point=(0.0, -25.0))
    p = tmp_path / "config.json"
    c.save(p)
    assert json.loads(p.read_text())["algo"] == "eql"
    assert Config.load(p) == c


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("bad.json", '{"gamma": 0.9,'),
        ("bad.yaml", "gamma: [0.9\n"),
        ("bad.yaml", "a: b: c\n"),
    ],
)
def test_broken_file_raises_config_error(tmp_path: Path, name: str, text: str) -> None:
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(ConfigError, match="could not be parsed"):
        Config.load(p)


def test_load_non_mapping_missing_file_and_bad_values(tmp_path: Path) -> None:
    p = tmp_path / "list.yaml"
    p.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="must hold a mapping"):
        Config.load(p)
    with pytest.raises(ConfigError, match="does not exist"):
        Config.load(tmp_path / "nope.json")
    q = tmp_path / "bad_value.json"
    q.write_text('{"gamma": 1.5}')
    with pytest.raises(ConfigError, match=r"gamma=1\.5"):
        Config.load(q)
    r = tmp_path / "typo.yaml"
    r.write_text("sigma_omgea: 0.1\n")
    with pytest.raises(ConfigError, match="did you mean 'sigma_omega'"):
        Config.load(r)


# ------------------------------------------------------------------------------------------- known bugs
@pytest.mark.parametrize("value", ["false", 2])
def test_non_bool_exploration_switch_raises_config_error(value: object) -> None:
    with pytest.raises(ConfigError, match="experience_exploration"):
        Config.from_dict({"experience_exploration": value}).to_dict()


@pytest.mark.parametrize(
    "data",
    [{"max_episode_steps": "100"}, {"hidden_sizes": 64}, {"hidden_sizes": "abc"}, {"ref_point": "abc"}],
)
def test_wrong_typed_values_raise_config_error(data: dict) -> None:
    with pytest.raises(ConfigError, match=next(iter(data))):
        Config.from_dict(data)


# ------------------------------------------------------------------------------------------- presets
#: The defaults of mope 0.1 (before the learning study), which the paper preset must reproduce exactly.
OLD_DEFAULTS = {"q_head": "conditioned", "obs_encoding": "scale", "hidden_sizes": [64, 128, 128, 64],
                "learning_rate": 1e-3, "learning_rate_end": None, "batch_size": 32, "target_tau": None,
                "target_update_freq": 100, "max_grad_norm": 10.0, "n_omega": 64, "relabel_broad": 0.0,
                "envelope_prefs": "relabel", "lb_homotopy_steps": 0, "learning_starts": 200, "gamma": 0.99,
                "double_q": True, "clip_targets": True, "epsilon_decay_steps": 10_000, "epsilon_end": 0.05,
                "per_alpha": 0.6, "sigma_omega": 0.04, "mi_alpha": 0.1, "n_intervals": 10, "buffer_size": 20_000,
                "lb_weight": 1.0, "return_mix": 0.0, "n_step": 1}


def test_presets() -> None:
    paper = Config.from_dict({"preset": "paper"}).to_dict()
    assert {k: paper[k] for k in OLD_DEFAULTS} == OLD_DEFAULTS
    env = Config.for_algo("eql", preset="envelope", seed=3)
    assert env.hidden_sizes == (256,) * 4 and env.n_omega == 4 and env.max_grad_norm == 0.1
    assert env.lb_homotopy_steps == 10_000 and env.target_update_freq == 1000 and env.seed == 3
    assert (env.lb_loss, env.lb_weight, Config().lb_weight) == ("squared", 1.0, 4.0)  # morl-baselines: MSE, to 1
    assert env.return_mix == 0.0 and Config().return_mix == 0.5  # the peer has no behaviour returns; mope has
    assert (env.n_step, env.epsilon_decay_steps) == (1, 10_000)
    assert Config.from_dict({"preset": "paper", "batch_size": 8}).batch_size == 8  # keys override the preset
    assert Config.from_dict({"preset": "mope"}) == Config()
    with pytest.raises(ConfigError, match="unknown preset 'papr' \\(did you mean 'paper'\\?\\)"):
        Config.from_dict({"preset": "papr"})


def test_exploration_and_buffer_follow_the_run_length_unless_set() -> None:
    from mope.config import ENV_DEFAULTS, buffer_capacity, epsilon_decay_steps_of

    def resolved(c: Config) -> tuple[int, int]:
        return epsilon_decay_steps_of(c), buffer_capacity(c)

    # half the run and the whole run; Deep-Sea-Treasure's 20k (and anything shorter) keeps 10k and 20k
    assert [resolved(Config(total_steps=t)) for t in (500, 20_000, 50_000, 100_000, 3_000_000)] == [
        (10_000, 20_000), (10_000, 20_000), (25_000, 50_000), (50_000, 100_000), (1_500_000, 1_000_000)]
    assert resolved(Config(total_steps=100_000, epsilon_decay_steps=7, buffer_size=300)) == (7, 300)
    c = Config(total_steps=100_000)
    assert c.to_dict()["buffer_size"] is None and resolved(Config.from_dict(c.to_dict())) == (50_000, 100_000)
    assert resolved(c.replace(total_steps=60_000)) == (30_000, 60_000)  # None follows a changed budget
    # the presets and the robot game keep their fixed values
    assert resolved(Config.from_dict({"preset": "paper", "total_steps": 100_000})) == (10_000, 20_000)
    assert resolved(Config.for_algo("eql", preset="envelope", total_steps=100_000)) == (10_000, 20_000)
    game = Config.from_dict({"env_id": next(iter(ENV_DEFAULTS)), "total_steps": 200_000})
    assert resolved(game) == (10_000, 100_000)
    with pytest.raises(ConfigError, match=r"buffer_size=-1 is out of range: must be >= batch_size"):
        Config(buffer_size=-1)  # named as itself, not through n_envs' bound
    with pytest.raises(ConfigError, match=r"epsilon_decay_steps=0 is out of range: must be >= 1 or None"):
        Config(epsilon_decay_steps=0)
    with pytest.raises(ConfigError, match=r"n_envs=20 is out of range: must lie in \[1, 16\]"):
        Config(n_envs=20, buffer_size=32, batch_size=32)


def test_the_agent_explores_over_half_a_long_run() -> None:
    from mope import MoPE

    agent = MoPE("deep-sea-treasure-v0", total_steps=100_000, hidden_sizes=(8,), n_omega=2)
    agent.global_step = 40_000
    assert agent.epsilon == pytest.approx(1.0 - 0.95 * 0.8)  # with the old fixed 10k it was at its floor, 0.05
    assert agent.buffer.capacity == 100_000


def test_a_config_saved_by_mope_0_1_reads_with_the_defaults_it_was_trained_with() -> None:
    saved = {**{k: v for k, v in OLD_DEFAULTS.items() if k not in ("q_head", "learning_rate_end", "target_tau",
                                                                   "relabel_broad", "lb_homotopy_steps")},
             "extra": {}, "algo": "mope", "seed": 1}
    c = Config.from_dict(saved)
    assert c.q_head == "conditioned" and c.target_tau is None and c.relabel_broad == 0.0 and c.seed == 1
    assert c.learning_rate_end is None and c.return_mix == 0.0 and c.n_step == 1 and c.epsilon_decay_steps == 10_000


def test_a_config_saved_before_the_later_fields_keeps_the_values_it_ran_with() -> None:
    from mope.config import LATER_FIELDS

    saved = {k: v for k, v in Config().to_dict().items() if k not in LATER_FIELDS}
    old = Config.from_dict(saved)
    assert {k: getattr(old, k) for k in LATER_FIELDS} == LATER_FIELDS
    partial = Config.from_dict({"q_head": "convex", "seed": 3})  # a user's overrides get today's defaults
    assert {k: getattr(partial, k) for k in LATER_FIELDS} == {k: getattr(Config(), k) for k in LATER_FIELDS}


# ------------------------------------------------------------------------------------------- --set parsing
def test_parse_overrides_reads_json_lists_presets_and_strings() -> None:
    from mope.config import parse_overrides

    got = parse_overrides(["n-step=5", "target_tau=0.01", "hidden_sizes=64,64", "disc_hidden=[16]",
                           "obs_encoding=onehot", "double_q=false", "preset=paper", "max_episode_steps=null"])
    assert got == {"n_step": 5, "target_tau": 0.01, "hidden_sizes": [64, 64], "disc_hidden": [16],
                   "obs_encoding": "onehot", "double_q": False, "preset": "paper", "max_episode_steps": None}
    assert Config.from_dict(got).n_step == 5


@pytest.mark.parametrize(("items", "message"), [
    (["n_step"], "'n_step' is not KEY=VALUE"),
    (["n_stp=5"], "n_stp"),
    (["hidden_sizes=a,b"], "comma-separated list of integers"),
    (["preset=nope"], "nope"),
])
def test_parse_overrides_refuses_bad_items_by_name(items: list[str], message: str) -> None:
    from mope.config import parse_overrides

    with pytest.raises(ConfigError, match=message):
        parse_overrides(items)


def test_one_set_parser_serves_train_and_sweep() -> None:
    """JSON first (``1e-3`` is a number, which YAML 1.1 would keep as a string), then YAML (flow lists), else the
    string; a sweep's ``--set`` reads values the same way and checks its keys itself."""
    from mope.config import parse_set
    from mope.experiments.sweep import SweepError
    from mope.experiments.sweep import parse_set as sweep_parse_set

    items = ["learning_rate=1e-3", "hidden_sizes=[8, 8]", "disc_hidden=16,16", "q_head=convex", "target_tau=null",
             "seed=[0, 1]", "envelope_prefs=[relabel, own]"]
    want = {"learning_rate": 1e-3, "hidden_sizes": [8, 8], "disc_hidden": [16, 16], "q_head": "convex",
            "target_tau": None, "seed": [0, 1], "envelope_prefs": ["relabel", "own"]}
    assert parse_set(items) == sweep_parse_set(items) == want
    with pytest.raises(SweepError, match="is not KEY=VALUE"):
        sweep_parse_set(["oops"])
    # a plain word stays the word: an empty value switches demonstrations off, "yes" is no boolean
    assert parse_set(["demos=", "obs_encoding=yes", "q_head=~"]) == {"demos": "", "obs_encoding": "yes", "q_head": "~"}
    assert Config.from_dict({"env_id": "mope/RobotConfrontationDiscrete-v0", **parse_set(["demos="])}).demos == ""
    # Python's None is null where a setting takes null, and stays a word elsewhere (then refused by its type check)
    assert parse_set(["reward_norm=None", "seen_bound_margin=none", "ref_point=None", "demos=None", "gamma=None"]) == {
        "reward_norm": None, "seen_bound_margin": None, "ref_point": None, "demos": "None", "gamma": "None"}
    with pytest.raises(ConfigError, match="gamma='None' is not a number"):
        Config.from_dict(parse_set(["gamma=None"]))
    assert parse_set(["totl_steps=3"]) == {"totl_steps": 3}  # keys are checked by the caller ...
    with pytest.raises(ConfigError, match="totl_steps"):
        parse_set(["totl_steps=3"], check_keys=True)  # ... or here
