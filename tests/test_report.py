"""`mope report` on small, fixed, hand-written run folders with known numbers."""

from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from mope.config import Config
from mope.experiments.report import ReportError, find_runs, report
from mope.experiments.runs import METRIC_COLUMNS
from mope.experiments.stats import aggregate, bootstrap_ci, iqm

# final (step 300) values per algorithm and seed: cr, hv, eum, optimal_share, timeout_share
FINAL = {
    "eql": [(0.2, 100.0, -10.0, 0.1, 0.5), (0.4, 120.0, -8.0, 0.2, 0.4), (0.6, 140.0, -6.0, 0.3, 0.3),
            (1.0, 200.0, 2.0, 0.9, 0.0)],
    "mope": [(0.5, 150.0, -4.0, 0.5, 0.2)] * 4,
}


def write_run(folder: Path, algo: str, seed: int, final: tuple[float, ...], total_steps: int = 300,
              finished: bool = True, **overrides: object) -> None:
    """A run folder as train_run writes it: config.json, metrics.csv (3 evaluations), solutions.csv, summary."""
    folder.mkdir(parents=True)
    cfg = Config.for_algo(algo, seed=seed, total_steps=total_steps, eval_every=100, **overrides)
    cfg.save(folder / "config.json")
    cr, hv, eum, opt, to = final
    with open(folder / "metrics.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=METRIC_COLUMNS)
        w.writeheader()
        steps = [100, 200, 300] if finished else [100]
        for i, step in enumerate(steps):
            scale = (i + 1) / len(steps)  # the curve rises to the final values
            row = {k: 0.0 for k in METRIC_COLUMNS}
            row.update(step=step, wall_s=1.0 + i, cr=cr * scale, hv=hv * scale, eum=eum * scale,
                       optimal_share=opt * scale, timeout_share=to * scale,
                       igd=math.nan, path_error=math.nan, overestimation=math.nan, win_share=math.nan,
                       out_share=math.nan)  # the report leaves an all-NaN metric out
            w.writerow(row)
    with open(folder / "solutions.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["w0", "w1", "disc0", "disc1", "ret0", "ret1", "length", "terminated"])
        w.writerow([0.9, 0.1, 0.7, -1.0, 0.7, -1.0, 1, 1])
        w.writerow([0.1, 0.9, 8.0 + seed, -3.0, 8.0, -3.0, 3, 1])
    if finished:
        (folder / "summary.json").write_text(json.dumps({"final": {"cr": cr}, "wall_s": 3.0}))


def write_sweep(root: Path) -> None:
    for algo, finals in FINAL.items():
        for seed, final in enumerate(finals):
            write_run(root / f"deep-sea-treasure-v0-{algo}-s{seed}", algo, seed, final)
    (root / "sweep.json").write_text(json.dumps({"swept": ["algo", "seed"], "trials": []}))


def test_statistics_by_hand() -> None:
    x = [0.2, 0.4, 0.6, 1.0]
    s = aggregate(x, n_boot=10_000, seed=0)
    assert s.n == 4 and s.mean == pytest.approx(0.55)
    assert s.std == pytest.approx(math.sqrt(0.35 / 3))  # sample std, ddof 1
    assert s.iqm == pytest.approx(0.5)  # middle two of four
    rng = np.random.default_rng(0)  # the percentile bootstrap, spelled out
    means = np.asarray(x)[rng.integers(0, 4, size=(10_000, 4))].mean(axis=1)
    assert (s.ci_low, s.ci_high) == pytest.approx(tuple(np.percentile(means, [2.5, 97.5])))
    assert 0.2 <= s.ci_low < 0.55 < s.ci_high <= 1.0
    assert bootstrap_ci([3.0, 3.0, 3.0]) == (3.0, 3.0)
    assert iqm([1, 2, 3, 4, 5, 6, 7, 100]) == pytest.approx(4.5)  # the outlier is trimmed
    one = aggregate([0.7])
    assert (one.mean, one.std, one.ci_low, one.ci_high) == (0.7, 0.0, 0.7, 0.7)
    assert aggregate([math.nan, 1.0, 3.0]).n == 2  # NaN values are left out


def test_report_table_on_fixed_runs(tmp_path: Path) -> None:
    write_sweep(tmp_path)
    res = report(tmp_path, tmp_path / "out", n_boot=10_000)
    assert [g.label for g in res.groups] == ["eql", "mope"]
    assert res.metrics == ["cr", "hv", "eum", "optimal_share", "timeout_share"]
    eql = res.groups[0].stats
    assert eql["cr"].mean == pytest.approx(0.55) and eql["cr"].std == pytest.approx(0.341565, abs=1e-6)
    assert eql["hv"].mean == pytest.approx(140.0) and eql["hv"].iqm == pytest.approx(130.0)
    assert eql["eum"].mean == pytest.approx(-5.5) and eql["eum"].iqm == pytest.approx(-7.0)
    lo, hi = bootstrap_ci([0.2, 0.4, 0.6, 1.0], 10_000, 0)
    mope = res.groups[1].stats
    assert (mope["cr"].mean, mope["cr"].std, mope["cr"].ci_low, mope["cr"].ci_high) == (0.5, 0.0, 0.5, 0.5)
    lines = res.table.splitlines()
    assert lines[0] == ("| group | seeds | steps | CR | HV | EUM | optimal share | time-outs | CR IQM | HV IQM "
                        "| EUM IQM | optimal share IQM | time-outs IQM |")
    assert lines[2].startswith(f"| eql | 4 | 300 | 0.550 ± 0.342 [{lo:.3f}, {hi:.3f}] | 140.0 ± 43.2 [")
    assert lines[2].endswith("| 0.500 | 130.0 | -7.00 | 0.250 | 0.350 |")
    assert lines[3] == ("| mope | 4 | 300 | 0.500 ± 0.000 [0.500, 0.500] | 150.0 ± 0.0 [150.0, 150.0] | "
                        "-4.00 ± 0.00 [-4.00, -4.00] | 0.500 ± 0.000 [0.500, 0.500] | 0.200 ± 0.000 [0.200, 0.200] | "
                        "0.500 | 150.0 | -4.00 | 0.500 | 0.200 |")
    assert res.table in (tmp_path / "out" / "report.md").read_text()
    doc = json.loads((tmp_path / "out" / "report.json").read_text())
    assert doc["groups"][0]["stats"]["cr"]["values"] == [0.2, 0.4, 0.6, 1.0]
    assert doc["groups"][0]["stats"]["cr"]["ci_low"] == pytest.approx(lo)
    for name in ("curves.png", "fronts.png"):
        assert (tmp_path / "out" / name).stat().st_size > 10_000


def test_env_without_front_reports_hv_and_eum_only(tmp_path: Path) -> None:
    for seed in range(2):
        write_run(tmp_path / f"r{seed}", "mope", seed, (math.nan, 10.0 + seed, 1.0, math.nan, 0.0))
    res = report(tmp_path, plots=False)
    assert res.metrics == ["hv", "eum", "timeout_share"]
    assert res.table.splitlines()[0] == "| group | seeds | steps | HV | EUM | time-outs |"
    assert res.groups[0].stats["hv"].mean == 10.5 and res.groups[0].stats["hv"].std == pytest.approx(math.sqrt(0.5))
    assert any("cr, igd, optimal_share" in n for n in res.notes)
    assert "IQM" not in res.table  # fewer than 4 seeds: the IQM equals the mean and is not shown


def test_mixed_configs_beyond_swept_fields_are_named(tmp_path: Path) -> None:
    write_sweep(tmp_path)
    write_run(tmp_path / "late-eql-s7", "eql", 7, FINAL["eql"][0], total_steps=400, learning_rate=5e-4)
    with pytest.raises(ReportError, match=r"beyond the seed and the swept fields \(algo\): total_steps: 300, 400; "
                                          r"learning_rate: 0.0003, 0.0005"):
        report(tmp_path, plots=False)
    res = report(tmp_path, plots=False, split_mismatched=True)
    assert [g.label for g in res.groups] == ["eql total_steps=300 learning_rate=0.0003",
                                             "mope total_steps=300 learning_rate=0.0003",
                                             "eql total_steps=400 learning_rate=0.0005"]
    assert [len(g.runs) for g in res.groups] == [4, 4, 1]


def test_without_sweep_json_varying_fields_define_groups(tmp_path: Path) -> None:
    for seed in range(2):
        write_run(tmp_path / "a" / f"s{seed}", "eql", seed, FINAL["eql"][seed], sigma_omega=0.02)
        write_run(tmp_path / "b" / f"s{seed}", "eql", seed, FINAL["eql"][seed + 2], sigma_omega=0.08)
    res = report(tmp_path, plots=False)
    assert [g.label for g in res.groups] == ["sigma_omega=0.02", "sigma_omega=0.08"]
    assert res.groups[1].stats["cr"].mean == pytest.approx(0.8)
    assert any("sigma_omega" in n for n in res.notes)


def test_unfinished_runs_are_left_out_and_errors_are_clear(tmp_path: Path) -> None:
    write_run(tmp_path / "done", "eql", 0, FINAL["eql"][0])
    write_run(tmp_path / "half", "eql", 1, FINAL["eql"][1], finished=False)
    runs, notes = find_runs(tmp_path)
    assert [r.path.name for r in runs] == ["done"]
    assert notes == ["left out half: unfinished (last evaluation at step 100 of 300)"]
    with pytest.raises(ReportError, match="unknown metric 'hvv' \\(did you mean 'hv'\\?\\)"):
        report(tmp_path, metrics=("hvv",))
    with pytest.raises(ReportError, match="no finished run folders"):
        report(tmp_path / "half")
    with pytest.raises(ReportError, match="does not exist"):
        report(tmp_path / "nope")
    write_run(tmp_path / "dupe", "eql", 0, FINAL["eql"][2])
    with pytest.raises(ReportError, match="holds seed 0 twice"):
        report(tmp_path, plots=False)


def test_a_sweep_with_arms_is_grouped_by_arm(tmp_path: Path) -> None:
    trials = []
    for arm, overrides, finals in (("default", {}, FINAL["mope"][:2]),
                                   ("paper", {"hidden_sizes": [64, 128, 128, 64], "learning_rate": 1e-3},
                                    FINAL["eql"][:2])):
        for seed, final in enumerate(finals):
            name = f"deep-sea-treasure-v0-mope-{arm}-s{seed}"
            write_run(tmp_path / name, "mope", seed, final, **overrides)
            trials.append({"name": name, "params": {"arm": arm, "seed": seed}})
    (tmp_path / "sweep.json").write_text(json.dumps({"swept": ["arm", "seed"], "trials": trials,
                                                     "arm_fields": ["hidden_sizes", "learning_rate"]}))
    res = report(tmp_path, plots=False)
    assert [g.label for g in res.groups] == ["default", "paper"]
    assert res.groups[1].stats["cr"].mean == pytest.approx(0.3)


def test_coverage_over_time_counts_first_cr1_and_the_drop(tmp_path: Path) -> None:
    write_sweep(tmp_path)
    res = report(tmp_path, plots=False)
    text = (tmp_path / "report" / "report.md").read_text()
    # the hand-made curves rise linearly to the final CR: only the eql seed with final CR 1.0 reaches it, at step 300
    assert "| eql | 1/4 | never | never, never, never, 300 | 0.000 [0.000, 0.000] |" in text
    doc = json.loads((tmp_path / "report" / "report.json").read_text())
    assert doc["groups"][0]["coverage"]["first_cr1"] == [None, None, None, 300]
    assert res.groups[0].label == "eql"


def test_runs_saved_before_a_field_existed_group_with_todays(tmp_path: Path) -> None:
    """A run saved before ``layer_norm`` and ``reward_norm`` existed reads the values it ran with (``migrate``), a
    norm that does not act on the environment is no difference, and 25 (``--set reward_norm=25``) is 25.0."""
    write_run(tmp_path / "s0", "mope", 0, FINAL["mope"][0], env_id="deep-sea-treasure-mirrored-v0", reward_norm=25)
    write_run(tmp_path / "s1", "mope", 1, FINAL["mope"][1], env_id="deep-sea-treasure-mirrored-v0")
    write_run(tmp_path / "s2", "mope", 2, FINAL["mope"][2], env_id="deep-sea-treasure-mirrored-v0")
    old = json.loads((tmp_path / "s2" / "config.json").read_text())
    del old["layer_norm"]  # saved before the field existed
    (tmp_path / "s2" / "config.json").write_text(json.dumps(old))
    dst_old, dst_new = tmp_path / "dst" / "s0", tmp_path / "dst" / "s1"
    write_run(dst_old, "mope", 0, FINAL["mope"][0], reward_norm=None)
    write_run(dst_new, "mope", 1, FINAL["mope"][1])
    assert [len(g.runs) for g in report(tmp_path / "dst", plots=False).groups] == [2]  # the norm is inert on DST
    shutil.rmtree(tmp_path / "dst")
    res = report(tmp_path, plots=False)
    assert [len(g.runs) for g in res.groups] == [3]
