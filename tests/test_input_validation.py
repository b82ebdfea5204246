"""Input validation: every guarded input, from the Python API and from the CLI.

Each bad input must raise a :class:`mope.MopeError` subclass whose one-line message names the bad value and what
is allowed (API), and make the CLI exit with code 2 after one ``error: ...`` line and no traceback. The CLI cases
here run in-process with typer's ``CliRunner`` (milliseconds each); tests/test_cli.py runs the real ``mope``
process end to end. Cases tested elsewhere are listed by file, so each case has exactly one home.

Case -> tests (``here`` = this file; tests elsewhere by file::name):

* preference: wrong length, negative, NaN, not summing to 1, empty, junk -- API:
  test_preferences::test_validate_preference_rejects, test_agent::test_act_single_and_batch_and_bad_preferences;
  CLI: test_cli::test_act_rejects_bad_preferences. Here: test_api_bad_preference_shapes (inf, not numbers,
  a scalar, None, 3-d, empty string), test_cli_act_bad_preference (inf, empty).
* unknown environment -- API: test_agent::test_unknown_environment_and_continuous_actions_are_named;
  CLI: test_cli::test_bad_input_exits_2_with_one_clear_line.
* unknown algorithm -- API: test_config::test_for_algo_unknown_suggests, here: test_api_make_agent_unknown_algo;
  CLI: test_cli::test_bad_input_exits_2_with_one_clear_line.
* unknown config key -- API: test_config::test_unknown_key_suggests_closest, here: test_api_unknown_keyword_argument
  (Config(...) and MoPE(...) keywords); CLI: test_cli (--set), here: test_cli_config_file (YAML).
* config file with an unknown key, a wrong type, an out-of-range value, unparsable -- API:
  test_config::test_load_non_mapping_missing_file_and_bad_values, here: test_api_config_file; CLI: here:
  test_cli_config_file.
* out of range: sigma_omega <= 0, N_omega < 1, alpha < 0, N_I < 1, gamma outside (0, 1], batch > buffer,
  steps < 1 -- API: test_config::test_out_of_range_raises_config_error_naming_field_and_value, here:
  test_api_agent_out_of_range (through MoPE(...)), test_api_train_steps; CLI: test_cli (sigma, n_omega,
  gamma 1.5, batch > buffer, steps 0), here: test_cli_out_of_range (alpha, N_I, gamma 0).
* continuous-action environment -- API: here: test_api_continuous_env_names_the_wrapper,
  test_discrete_actions_wrapper_makes_it_usable; CLI: test_cli (mo-mountaincarcontinuous-v0).
* missing output folder (created) -- test_checkpoint::test_save_creates_parent_folders_and_overwrites, here:
  test_api_missing_output_folder_is_created.
* unwritable output folder -- API: test_run_folders::test_output_folder_that_cannot_be_created_is_named, here:
  test_api_unwritable_output (Config.save, MoPE.save), test_api_read_only_output_folder (chmod; skipped as
  root); CLI: here: test_cli_unwritable_out.
* checkpoint carries format version, package version and config; read with weights_only=True --
  test_checkpoint::test_round_trip, here: test_agent_checkpoint_carries_versions_and_config.
* malicious checkpoint (unpickling would create a file): refused, file not created --
  test_checkpoint::test_malicious_checkpoint_is_refused_without_running, here:
  test_api_malicious_agent_checkpoint (MoPE.load), test_cli_malicious_checkpoint (eval and act).
* truncated, corrupt, random bytes -- test_checkpoint::test_truncated_file, test_random_bytes,
  test_cli::test_broken_checkpoint_is_named, here: test_damaged_agent_checkpoints_are_refused,
  test_flipped_byte_in_weights_is_caught, test_cli_truncated_checkpoint.
* checkpoint of another environment or number of objectives -- test_agent::test_load_refuses_an_incompatible_
  environment, here: test_check_compatible_names_the_mismatch, test_load_into_other_number_of_objectives_is_named,
  test_load_into_same_shaped_other_env. (The CLI always loads a checkpoint into its own environment.)
* atomic writes -- test_checkpoint::test_crash_during_write_keeps_previous_file.
* one-line messages -- here: test_mope_error_is_one_line, and every assertion helper below.
"""

from __future__ import annotations

import builtins
import os
import struct
import sys
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

import mope
import mope.agent.checkpoint as checkpoint
from mope import EQL, MoPE
from mope.agent.checkpoint import FORMAT_VERSION, check_compatible, load_checkpoint, mope_version
from mope.cli import app
from mope.config import Config
from mope.envs import DiscreteActions, make_env
from mope.errors import CheckpointError, ConfigError, EnvironmentError_, MopeError, PreferenceError

SMALL = {"n_omega": 4, "hidden_sizes": (16,), "disc_hidden": (8,), "batch_size": 8, "buffer_size": 64,
         "learning_starts": 10, "eval_prefs": 20}
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


class Evil:
    """Unpickling this creates a file: what a checkpoint loader must refuse without running it."""

    def __init__(self, target: Path) -> None:
        self.target = str(target)

    def __reduce__(self):  # noqa: ANN204
        return (builtins.open, (self.target, "w"))


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real (untrained) EQL checkpoint on Deep-Sea-Treasure, with its replay buffer."""
    agent = EQL("deep-sea-treasure-v0", **SMALL)
    return agent.save(tmp_path_factory.mktemp("ckpt") / "eql.pt", include_buffer=True)


def cli(*args: str) -> object:
    return CliRunner().invoke(app, list(args))


def assert_cli_error(res: object, *needles: str) -> None:
    """Exit code 2, exactly one ``error:`` line on stderr naming ``needles``, and no traceback."""
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    assert "Traceback" not in res.output
    for needle in needles:
        assert needle in lines[0], lines[0]


def raises(exc: type[Exception], fn: Callable[[], object], *needles: str) -> str:
    with pytest.raises(exc) as info:
        fn()
    msg = str(info.value)
    assert "\n" not in msg
    for needle in needles:
        assert needle in msg, msg
    return msg


# ======================================================================================= part 1: the Python API
def test_mope_error_is_one_line() -> None:
    assert str(MopeError("first line\n  second line\n")) == "first line second line"
    assert str(ConfigError("a\nb")) == "a b"


@pytest.mark.parametrize(
    ("pref", "needles"),
    [
        ([float("inf"), 0.0], ["inf", "finite"]),
        (["a", "b"], ["['a', 'b']", "not a list of numbers", "2 weights"]),
        (0.5, ["0.5", "not a list of weights"]),
        (None, ["None", "not a list of weights"]),
        ([[[0.5, 0.5]]], ["shape (1, 1, 2)", "(2,) or (n, 2)"]),
        ("", ["empty", "2 comma-separated weights"]),
    ],
)
def test_api_bad_preference_shapes(pref: object, needles: list[str]) -> None:
    agent = EQL("deep-sea-treasure-v0", **SMALL)
    obs, _ = agent.env.reset(seed=0)
    raises(PreferenceError, lambda: agent.act(obs, pref), *needles)


def test_api_make_agent_unknown_algo() -> None:
    raises(ConfigError, lambda: mope.make_agent("mop", "deep-sea-treasure-v0"), "'mop'", "did you mean 'mope'",
           "eql, ee, pe, mope")


def test_api_unknown_keyword_argument() -> None:
    raises(ConfigError, lambda: Config(sigma_omgea=0.1), "'sigma_omgea'", "did you mean 'sigma_omega'")
    raises(ConfigError, lambda: MoPE("deep-sea-treasure-v0", n_omgea=8), "'n_omgea'", "did you mean 'n_omega'")
    raises(ConfigError, lambda: Config(zzzzzz=1), "'zzzzzz'", "fields of mope.Config")


@pytest.mark.parametrize(
    ("text", "exc_needles"),
    [
        ("n_omega: '64'\n", ["n_omega='64'", "not an integer"]),
        ("n_omega: 0.5\n", ["n_omega=0.5", "not an integer"]),
        ("per: 1\n", ["per=1", "true or false"]),
        ("hidden_sizes: 64\n", ["hidden_sizes=64", "list of integers"]),
        ("sigma_omega: 0\n", ["sigma_omega=0", "must be > 0"]),
        ("gamma: 0\n", ["gamma=0", "(0, 1]"]),
        ("batch_size: 64\nbuffer_size: 32\n", ["buffer_size=32", "batch_size (64)"]),
        ("total_steps: 0\n", ["total_steps=0", ">= 1"]),
        ("algo: mopee\n", ["'mopee'", "did you mean 'mope'"]),
        ("gamma: [0.9\n", ["could not be parsed", "line 2, column 1"]),
        ("- 1\n- 2\n", ["must hold a mapping"]),
    ],
)
def test_api_config_file(tmp_path: Path, text: str, exc_needles: list[str]) -> None:
    path = tmp_path / "run.yaml"
    path.write_text(text)
    raises(ConfigError, lambda: Config.load(path), *exc_needles)


def test_api_config_file_unreadable(tmp_path: Path) -> None:
    path = tmp_path / "binary.json"
    path.write_bytes(b"\xff\xfe\x00garbage")
    raises(ConfigError, lambda: Config.load(path), "binary.json", "could not be read")


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"sigma_omega": 0.0}, ["sigma_omega=0.0", "must be > 0"]),
        ({"sigma_omega": -0.04}, ["sigma_omega=-0.04", "must be > 0"]),
        ({"n_omega": 0}, ["n_omega=0", "must be >= 1"]),
        ({"mi_alpha": -0.1}, ["mi_alpha=-0.1", "must be >= 0"]),
        ({"n_intervals": 0}, ["n_intervals=0", "must be >= 1"]),
        ({"gamma": 0.0}, ["gamma=0.0", "(0, 1]"]),
        ({"gamma": 1.5}, ["gamma=1.5", "(0, 1]"]),
        ({"batch_size": 64, "buffer_size": 32}, ["buffer_size=32", "batch_size (64)"]),
        ({"total_steps": 0}, ["total_steps=0", "must be >= 1"]),
        ({"n_omega": True}, ["n_omega=True", "not an integer"]),
    ],
)
def test_api_agent_out_of_range(changes: dict, needles: list[str]) -> None:
    raises(ConfigError, lambda: MoPE("deep-sea-treasure-v0", **changes), *needles)


def test_api_train_steps() -> None:
    agent = EQL("deep-sea-treasure-v0", **SMALL)
    raises(MopeError, lambda: agent.train(0), "total_timesteps=0", ">= 1")


def test_api_continuous_env_names_the_wrapper() -> None:
    msg = raises(EnvironmentError_, lambda: MoPE("mo-mountaincarcontinuous-v0"), "'mo-mountaincarcontinuous-v0'",
                 "continuous action space", "discrete action wrapper")
    assert "DiscreteActions" in msg


def test_discrete_actions_wrapper_makes_it_usable() -> None:
    import mo_gymnasium as mo_gym

    env = DiscreteActions(mo_gym.make("mo-mountaincarcontinuous-v0"), bins=3)
    assert env.action_space.n == 3
    np.testing.assert_allclose([env.action(a)[0] for a in range(3)], [-1.0, 0.0, 1.0])
    agent = EQL(env, **SMALL)
    agent.train(20)
    assert agent.global_step == 20 and agent.n_actions == 3
    raises(EnvironmentError_, lambda: DiscreteActions(mo_gym.make("mo-mountaincarcontinuous-v0"), bins=1), "bins=1")
    raises(EnvironmentError_, lambda: DiscreteActions(make_env("deep-sea-treasure-v0")), "needs a Box action space")


def test_api_missing_output_folder_is_created(tmp_path: Path) -> None:
    from mope.experiments.runs import prepare_out_dir

    out = prepare_out_dir(tmp_path / "new" / "run")
    assert (out / "checkpoints").is_dir()


def test_api_unwritable_output(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")  # a file where a folder should be: not writable, even for root
    raises(ConfigError, lambda: Config().save(blocker / "config.json"), "config.json", "could not be written")
    agent = EQL("deep-sea-treasure-v0", **SMALL)
    raises(CheckpointError, lambda: agent.save(blocker / "run" / "a.pt"), "a.pt", "not writable")


@pytest.mark.skipif(IS_ROOT, reason="root can write into a read-only folder, so chmod cannot make one unwritable")
def test_api_read_only_output_folder(tmp_path: Path) -> None:
    from mope.experiments.runs import RunFolderError, prepare_out_dir

    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        raises(RunFolderError, lambda: prepare_out_dir(ro / "run"), "not writable")
        raises(CheckpointError, lambda: save_in(ro), "not writable")
    finally:
        ro.chmod(0o755)


def save_in(folder: Path) -> Path:
    return checkpoint.save_checkpoint(folder / "a.pt", {"config": {}})


# ======================================================================================= part 1: the CLI
@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("sigma_omgea: 0.1\n", ["unknown config key 'sigma_omgea'", "did you mean 'sigma_omega'"]),
        ("n_omega: '64'\n", ["n_omega='64' is not an integer"]),
        ("gamma: 1.5\n", ["gamma=1.5 is out of range", "(0, 1]"]),
        ("gamma: [0.9\n", ["could not be parsed", "line 2"]),
    ],
)
def test_cli_config_file(tmp_path: Path, text: str, needles: list[str]) -> None:
    path = tmp_path / "run.yaml"
    path.write_text(text)
    assert_cli_error(cli("train", "--config", str(path), "--out", str(tmp_path / "x")), *needles)
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--mi-alpha", "-1"], ["mi_alpha=-1.0", ">= 0"]),
        (["--n-intervals", "0"], ["n_intervals=0", ">= 1"]),
        (["--set", "gamma=0"], ["gamma=0", "(0, 1]"]),
        (["--config", "does-not-exist.yaml"], ["does-not-exist.yaml", "does not exist"]),
    ],
)
def test_cli_out_of_range(tmp_path: Path, args: list[str], needles: list[str]) -> None:
    assert_cli_error(cli("train", *args, "--out", str(tmp_path / "x")), *needles)


def test_cli_unwritable_out(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert_cli_error(cli("train", "--steps", "10", "--out", str(blocker / "run")), "not writable")
    assert_cli_error(cli("train", "--steps", "10", "--out", str(blocker)), "not a folder")


@pytest.mark.parametrize(("pref", "needles"), [("inf,0", ["inf", "finite"]), ("", ["empty"]), (" , ", ["empty"])])
def test_cli_act_bad_preference(ckpt: Path, pref: str, needles: list[str]) -> None:
    assert_cli_error(cli("act", str(ckpt), "--pref", pref), *needles)


def test_cli_eval_prefs_out_of_range(ckpt: Path) -> None:
    assert_cli_error(cli("eval", str(ckpt), "--prefs", "0"), "--prefs 0", ">= 1")


def test_cli_set_list_of_non_integers(tmp_path: Path) -> None:
    assert_cli_error(cli("train", "--set", "hidden_sizes=a,b", "--out", str(tmp_path / "x")), "hidden_sizes")


@pytest.mark.parametrize("args", [["train", "--steps", "abc"], ["train", "--sigma-omgea", "1"], ["act", "x.pt"]])
def test_cli_usage_error_is_one_line(args: list[str], monkeypatch: pytest.MonkeyPatch,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    from mope.cli import main

    monkeypatch.setattr(sys, "argv", ["mope", *args])
    with pytest.raises(SystemExit) as info:
        main()
    assert info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), lines


# ======================================================================================= part 2: checkpoints
def test_agent_checkpoint_carries_versions_and_config(ckpt: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[dict] = []
    real_load = torch.load

    def spy(*args: object, **kwargs: object) -> object:
        calls.append(kwargs)
        return real_load(*args, **kwargs)

    monkeypatch.setattr(checkpoint.torch, "load", spy)
    data = load_checkpoint(ckpt)
    assert data["format_version"] == FORMAT_VERSION
    assert data["mope_version"] == mope_version()
    assert Config.from_dict(data["config"]) == Config.for_algo("eql", **SMALL)
    assert calls and all(kw.get("weights_only") is True for kw in calls)


def test_api_malicious_agent_checkpoint(ckpt: Path, tmp_path: Path) -> None:
    # a genuine agent checkpoint with one field swapped for an object whose unpickling creates a file
    target = tmp_path / "pwned.txt"
    data = torch.load(ckpt, weights_only=True)
    data["episodes"] = Evil(target)
    evil = tmp_path / "evil.pt"
    torch.save(data, evil)
    raises(CheckpointError, lambda: MoPE.load(evil), "evil.pt", "refused", "could run code")
    assert not target.exists()


@pytest.mark.parametrize("command", ["eval", "act"])
def test_cli_malicious_checkpoint(tmp_path: Path, command: str) -> None:
    target = tmp_path / "pwned.txt"
    evil = tmp_path / "evil.pt"
    torch.save({"format_version": FORMAT_VERSION, "config": Config().to_dict(), "x": Evil(target)}, evil)
    extra = ["--pref", "0.5,0.5"] if command == "act" else []
    assert_cli_error(cli(command, str(evil), *extra), "evil.pt", "refused")
    assert not target.exists()


def test_cli_truncated_checkpoint(ckpt: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.pt"
    cut.write_bytes(ckpt.read_bytes()[: ckpt.stat().st_size // 2])
    assert_cli_error(cli("eval", str(cut)), "cut.pt", "truncated or corrupt")


def test_damaged_agent_checkpoints_are_refused(ckpt: Path, tmp_path: Path) -> None:
    raw = ckpt.read_bytes()
    rng = np.random.default_rng(0)
    path = tmp_path / "damaged.pt"
    refused = 0
    for i in range(60):
        if i % 2:  # truncated anywhere
            path.write_bytes(raw[: int(rng.integers(0, len(raw)))])
        else:  # a few random bytes overwritten
            b = bytearray(raw)
            for pos in rng.integers(0, len(b), size=int(rng.integers(1, 8))):
                b[pos] = (b[pos] + int(rng.integers(1, 256))) % 256
            path.write_bytes(bytes(b))
        try:
            MoPE.load(path)
        except CheckpointError as exc:  # anything else (IndexError, UnicodeDecodeError, ...) fails the test
            assert "damaged.pt" in str(exc) and "\n" not in str(exc)
            refused += 1
    assert refused >= 55  # a flip in zip padding can be harmless; every truncation and CRC mismatch is caught


def test_flipped_byte_in_weights_is_caught(ckpt: Path, tmp_path: Path) -> None:
    # torch's reader does not check the zip CRCs; load_checkpoint does, so silently wrong weights are refused
    raw = bytearray(ckpt.read_bytes())
    with zipfile.ZipFile(ckpt) as z:
        info = next(i for i in z.infolist() if "/data/" in i.filename and i.file_size >= 4)
    name_len, extra_len = struct.unpack("<HH", raw[info.header_offset + 26 : info.header_offset + 30])
    start = info.header_offset + 30 + name_len + extra_len  # the member's first data byte
    raw[start] ^= 0xFF
    bad = tmp_path / "flipped.pt"
    bad.write_bytes(bytes(raw))
    raises(CheckpointError, lambda: load_checkpoint(bad), "flipped.pt", "checksum")


def test_check_compatible_names_the_mismatch() -> None:
    data = {"config": {"env_id": "deep-sea-treasure-v0"}, "env": {"n_objectives": 2, "n_actions": 4,
                                                                   "obs_shape": [2]}}
    check_compatible(data, "a.pt", "deep-sea-treasure-v0", 2, 4, (2,))  # fits
    raises(CheckpointError, lambda: check_compatible(data, "a.pt", "four-room-v0", 3, 4, (14,)),
           "another environment", "another number of objectives", "'deep-sea-treasure-v0' (2 objectives",
           "'four-room-v0' (3 objectives")
    raises(CheckpointError, lambda: check_compatible(data, "a.pt", None, 2, 5, (2,)), "another number of actions")
    raises(CheckpointError, lambda: check_compatible(data, "a.pt", "deep-sea-treasure-concave-v0", 2, 4, (2,)),
           "another environment", "'deep-sea-treasure-concave-v0'")
    check_compatible(data, "a.pt", "deep-sea-treasure-concave-v0", 2, 4, (2,), same_env=False)


def test_load_into_other_number_of_objectives_is_named(ckpt: Path) -> None:
    raises(CheckpointError, lambda: MoPE.load(ckpt, env=make_env("four-room-v0")), "eql.pt", "deep-sea-treasure-v0",
           "2 objectives", "3 objectives")


def test_load_into_same_shaped_other_env(ckpt: Path) -> None:
    raises(CheckpointError, lambda: MoPE.load(ckpt, env=make_env("deep-sea-treasure-concave-v0")),
           "another environment", "deep-sea-treasure-v0", "deep-sea-treasure-concave-v0")
