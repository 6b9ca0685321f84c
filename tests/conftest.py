"""Shared test configuration."""

import os
import signal

import pytest
from hypothesis import HealthCheck, settings

# Torch and BLAS oversubscribe two cores; tests set one thread (CI sets it too).
os.environ.setdefault("OMP_NUM_THREADS", "1")

settings.register_profile(
    "default", deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("default")


@pytest.fixture(autouse=True, scope="session")
def interruptible_children() -> None:
    """Let the subprocesses the tests stop with SIGINT (mock fleets, `compare`) take it.

    A job started in the background by a non-interactive shell begins with SIGINT ignored, and
    an ignored signal stays ignored across exec: the children would never see the tests'
    Ctrl-C. A handler (not SIG_IGN) here is reset to the default in every child.
    """
    signal.signal(signal.SIGINT, signal.default_int_handler)
