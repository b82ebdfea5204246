"""`mope reproduce dst` end to end on a tiny budget: every figure and the table are written, runs are reused."""

from __future__ import annotations

import json

import pytest

from mope.errors import ConfigError
from mope.paper.dst import dst_jobs, reproduce_dst

TINY = {"eval_prefs": 200, "n_omega": 8, "learning_starts": 50, "hidden_sizes": [32, 32], "batch_size": 16}


@pytest.mark.slow
def test_reproduce_dst_writes_figures_and_table(tmp_path):
    res = reproduce_dst(tmp_path, seeds=2, steps=300, eval_every=150, algos=("eql", "mope"), workers=2,
                        progress=False, **TINY)
    for name in ("fig2a_cr.png", "fig2a_optimal_share.png", "fig2a_timeouts.png", "fig2b_front.png",
                 "fig3a_preferences.png", "fig3b_discriminator.png", "table.md", "results.json"):
        assert (tmp_path / name).is_file(), name
    table = (tmp_path / "table.md").read_text()
    assert table.count("\n") == 4 and "| eql |" in table and "| mope |" in table
    results = json.loads((tmp_path / "results.json").read_text())["results"]
    assert set(results) == {"eql", "mope"}
    for r in results.values():
        assert 0.0 <= r["cr"]["mean"] <= 1.0 and r["steps_to_cr1"]["seeds"] == 2
        assert r["paths_per_solution"]["mean"] >= 0 and r["mi_state_pref"]["mean"] >= 0
        assert r["mi_state_pref"]["ci_low"] <= r["mi_state_pref"]["mean"] <= r["mi_state_pref"]["ci_high"]
    # a second call reuses the finished runs instead of training again
    stamp = (tmp_path / "eql-s0" / "summary.json").stat().st_mtime
    reproduce_dst(tmp_path, seeds=2, steps=300, eval_every=150, algos=("eql", "mope"), workers=2, progress=False,
                  **TINY)
    assert (tmp_path / "eql-s0" / "summary.json").stat().st_mtime == stamp
    assert res["table"] == table.strip()


def test_reproduce_rejects_bad_arguments(tmp_path):
    with pytest.raises(ConfigError, match="unknown algorithm 'dqn'"):
        reproduce_dst(tmp_path, algos=("dqn",))
    with pytest.raises(ConfigError, match="seeds=0"):
        reproduce_dst(tmp_path, seeds=0)
    with pytest.raises(ConfigError, match="'5-' is not a count"):
        reproduce_dst(tmp_path, seeds="5-")


@pytest.mark.parametrize(("seeds", "names"), [(2, ["eql-s0", "mope-s0", "eql-s1", "mope-s1"]),
                                              ("5-6", ["eql-s5", "mope-s5", "eql-s6", "mope-s6"]),
                                              ("7,3", ["eql-s7", "mope-s7", "eql-s3", "mope-s3"]),
                                              ([4], ["eql-s4", "mope-s4"])])
def test_reproduce_seeds_take_a_count_a_range_or_a_list(seeds, names):
    jobs = dst_jobs(seeds, 300, 150, ("eql", "mope"))
    assert [j.name for j in jobs] == names
    assert [j.payload["seed"] for j in jobs] == [int(n.rsplit("-s", 1)[1]) for n in names]
