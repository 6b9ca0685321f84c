"""Shared test configuration."""

import os

from hypothesis import HealthCheck, settings

# Torch and BLAS oversubscribe two cores; tests set one thread (CI sets it too).
os.environ.setdefault("OMP_NUM_THREADS", "1")

settings.register_profile(
    "default", deadline=None, max_examples=60, suppress_health_check=[HealthCheck.too_slow]
)
settings.load_profile("default")
