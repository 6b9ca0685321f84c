"""Fixtures of the generalist's training tests."""

from __future__ import annotations

import pytest
from tiny_policy import tiny_run_cfg

from policies.generalist_train import export_generalist_run, train_generalist


@pytest.fixture(scope="module")
def start_policy(tmp_path_factory):
    """A policy file exported from a tiny run: what the self-shield runs start from."""
    tmp_path = tmp_path_factory.mktemp("start")
    out = tmp_path / "run"
    train_generalist(tiny_run_cfg(tmp_path), out)
    path = tmp_path / "start.safetensors"
    export_generalist_run(out, path, checkpoint="last")
    return path
