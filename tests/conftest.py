"""Shared test settings."""

from __future__ import annotations

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
