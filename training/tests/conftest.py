"""Shared test settings."""

import pytest
import torch


@pytest.fixture(autouse=True, scope="session")
def _single_torch_thread():
    # With other jobs on the 2 cores, OpenMP's second thread is often descheduled and every
    # operator waits for it (measured: 17x slower training steps); tests run on one thread.
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(previous)
