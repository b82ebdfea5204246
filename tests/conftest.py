"""Shared test settings."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
import torch


@pytest.fixture(autouse=True)
def one_torch_thread() -> Iterator[None]:
    # These networks are tiny; with a second intra-op thread on a busy 2-core machine torch spends its time
    # spinning (300 Adam steps: 0.3 s with one thread, 30+ s with two).
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def pytest_collection_modifyitems(config, items) -> None:
    """With pytest-xdist's ``worksteal`` (``-n 2 --dist worksteal``, the suite's command), each worker starts with a
    contiguous share of the tests and steals from the end of another's queue. Left in file order, the slow learning
    tests can land in one worker's share and run one after another at the end, while the other worker idles (on 2
    cores: 860 s of tests, where the work is about 570 s per worker). So the slow tests go to the fronts of the
    shares, round-robin, and the fast tests fill each share's end, where stealing balances them."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0") or 0)
    if workers < 2:
        return
    slow = [it for it in items if it.get_closest_marker("slow")]
    fast = [it for it in items if not it.get_closest_marker("slow")]
    size = -(-len(fast) // workers)
    shares = [[*slow[w::workers], *fast[w * size:(w + 1) * size]] for w in range(workers)]
    items[:] = [it for share in shares for it in share]
