"""`remarl-fc compare --quick`: the grid runs, resumes, and writes well-formed outputs."""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from policies.compare import CompareConfig
from policies.compare.report import episode_counts, table2_rows
from remarl_fc.cli import main

pytestmark = pytest.mark.timeout(180)

needs_torch = pytest.mark.skipif(
    importlib.util.find_spec("torch") is None,
    reason="reMARL and COMA need the train extra: pip install 'remarl-fc[train]'",
)


def wait_until(done: Callable[[], bool], timeout_s: float, what: str) -> None:
    """Poll ``done`` until it holds; fail, saying ``what`` did not happen, after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            pytest.fail(f"{what} within {timeout_s:.0f} s")
        time.sleep(0.05)


@pytest.mark.slow
@needs_torch
def test_quick_compare_two_methods_writes_every_output(tmp_path, capsys):
    out = tmp_path / "results"
    args = ["compare", "--quick", "--scenarios", "2u1o,3u2o", "--methods", "remarl,coma,e2coop"]
    assert main([*args, "--out", str(out), "--json"]) == 0
    printed = capsys.readouterr()
    paths = json.loads(printed.out)
    assert paths["cells"] == 6
    progress = printed.err.splitlines()  # one line per cell as it finishes, on stderr
    assert [line.split("]")[0] for line in progress if line.startswith("[")] == [
        f"[{k}/6" for k in range(1, 7)
    ]
    assert any(
        line.startswith("[") and " 2u1o e2coop seed 0: success " in line for line in progress
    )
    for name in ("learning_curves.png", "summary.md", "table2.md", "table2.csv", "config.json"):
        assert (out / name).stat().st_size > 0, name
    with (out / "table2.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    # Table 2 for every scenario of the grid; the paper's figures only where it has them (3u2o)
    assert [(r["scenario"], r["method"]) for r in rows] == [
        ("2u1o", "e2coop"),
        ("2u1o", "remarl"),
        ("3u2o", "e2coop"),
        ("3u2o", "remarl"),
    ]
    assert [r["paper_reaction_ms"] for r in rows[:2]] == ["", ""]
    assert float(rows[2]["paper_reaction_ms"]) == 480.0
    assert float(rows[3]["paper_energy"]) == 19.72
    table2 = (out / "table2.md").read_text()
    assert "| 2u1o | e2coop |" in table2 and "| 3u2o | remarl |" in table2
    summary = (out / "summary.md").read_text()
    assert "| 2u1o |" in summary and "| 3u2o |" in summary
    assert "remarl 20, coma 20, e2coop 5" in summary  # the quick preset's evaluation episodes
    with (out / "runs" / "2u1o" / "remarl" / "seed0" / "curve.csv").open() as fh:
        curve = list(csv.DictReader(fh))
    assert curve and set(curve[0]) == {"env_steps", "episode", "swarming_return", "success"}
    result = json.loads((out / "runs" / "3u2o" / "e2coop" / "seed0" / "result.json").read_text())
    assert {"success_rate", "energy_rad", "reaction_ms_median"} <= set(result)

    # a rerun resumes: every cell is already finished, nothing is trained again
    stamp = (out / "runs" / "2u1o" / "remarl" / "seed0" / "result.json").stat().st_mtime
    assert main([*args, "--out", str(out), "--json"]) == 0
    assert (out / "runs" / "2u1o" / "remarl" / "seed0" / "result.json").stat().st_mtime == stamp


@pytest.mark.slow
@needs_torch
def test_episode_flags_override_the_preset(tmp_path, capsys):
    out = tmp_path / "results"
    args = ["compare", "--quick", "--scenarios", "2u1o", "--methods", "remarl,e2coop"]
    assert main([*args, "--eval-episodes", "7", "--e2coop-episodes", "2", "--out", str(out)]) == 0
    runs = out / "runs" / "2u1o"
    assert json.loads((runs / "remarl" / "seed0" / "result.json").read_text())["episodes"] == 7
    assert json.loads((runs / "e2coop" / "seed0" / "result.json").read_text())["episodes"] == 2
    assert "remarl 7, e2coop 2" in (out / "summary.md").read_text()


def test_unknown_method_is_a_clear_error(tmp_path, capsys):
    assert main(["compare", "--methods", "dqn", "--out", str(tmp_path)]) == 2
    assert "unknown method" in capsys.readouterr().err


def test_episode_counts_come_from_the_results():
    cfg = CompareConfig(("3u2o",), ("remarl", "mappo", "e2coop"), out=Path("unused"))
    results = [
        {"method": "remarl", "episodes": 200.0},
        {"method": "mappo", "episodes": 100.0},
        {"method": "mappo", "episodes": 200.0},
    ]
    assert episode_counts(cfg, results) == "remarl 200, mappo 100–200"


def _cell(scenario: str, method: str, seed: int, scale: float) -> dict[str, float | str | int]:
    return {
        "scenario": scenario,
        "method": method,
        "seed": seed,
        "reaction_ms_median": 2.0 * scale,
        "energy_rad": 1.0 * scale,
        "mean_min_d_u2o_m": 30.0 * scale,
        "mean_min_d_u2u_m": 40.0 * scale,
        "success_rate": 0.5 * scale,
    }


def test_table2_comes_from_the_grids_scenarios_not_only_3u2o():
    cfg = CompareConfig(("5u1o", "3u2o"), ("remarl", "coma", "e2coop"), out=Path("unused"))
    results = [
        _cell("5u1o", "remarl", 0, 1.0),
        _cell("5u1o", "remarl", 1, 1.5),
        _cell("5u1o", "coma", 0, 1.0),  # not a Table 2 method
        _cell("3u2o", "e2coop", 0, 1.0),
        _cell("7u2o", "remarl", 0, 1.0),  # not in the grid
    ]
    rows = table2_rows(cfg, results)
    assert [(r["scenario"], r["method"]) for r in rows] == [("5u1o", "remarl"), ("3u2o", "e2coop")]
    first, second = rows
    assert first["energy_rad"] == 1.25  # the mean over the seeds
    assert first["mean_min_d_u2o_m"] == 37.5
    assert first["success_rate"] == 0.625
    assert first["paper_reaction_ms"] is None  # the paper has no 5u1o row
    assert second["paper_reaction_ms"] == 480.0
    assert second["paper_min_d_u2u_m"] == 40.31
    only_5u1o = CompareConfig(("5u1o",), ("remarl",), out=Path("unused"))
    assert [r["scenario"] for r in table2_rows(only_5u1o, results)] == ["5u1o"]


ORPHAN_SCRIPT = """
import concurrent.futures, multiprocessing, os, sys, time
from policies.compare import worker_setup
ctx = multiprocessing.get_context("spawn")
pool = concurrent.futures.ProcessPoolExecutor(
    1, mp_context=ctx, initializer=worker_setup, initargs=(os.getpid(), ctx.Event())
)
print(pool.submit(os.getpid).result(), flush=True)
pool.submit(time.sleep, 120)  # a long cell
time.sleep(120)
"""


def test_pool_workers_end_when_compare_is_killed():
    """A SIGKILLed `compare` must not leave its workers training as orphans."""
    import signal
    import subprocess
    import sys

    with subprocess.Popen(
        [sys.executable, "-c", ORPHAN_SCRIPT], stdout=subprocess.PIPE, text=True
    ) as parent:
        assert parent.stdout is not None
        worker = int(parent.stdout.readline())
        os.kill(worker, 0)  # alive, busy with its cell
        parent.send_signal(signal.SIGKILL)
        parent.wait(10)

    def worker_gone() -> bool:
        try:
            os.kill(worker, 0)
        except ProcessLookupError:
            return True
        return False

    try:
        wait_until(worker_gone, 15, "the worker did not end with its compare process")
    finally:
        if not worker_gone():
            os.kill(worker, signal.SIGKILL)


def _children(pid: int) -> set[int]:
    """Process ids whose parent is ``pid`` (from /proc)."""
    kids = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # gone meanwhile
        if int(fields[1]) == pid:
            kids.add(int(stat.parent.name))
    return kids


@pytest.mark.slow  # two spawned workers import torch and start training: about 10 s
@needs_torch
def test_ctrl_c_stops_the_workers_at_once_and_says_how_to_resume(tmp_path):
    import signal
    import subprocess
    import sys

    args = ["compare", "--scenarios", "2u1o", "--methods", "remarl,coma", "--seeds", "1"]
    args += ["--budget", "1000000", "--workers", "2", "--out", str(tmp_path)]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    with subprocess.Popen(
        [sys.executable, "-m", "remarl_fc", *args], stderr=subprocess.PIPE, text=True, env=env
    ) as parent:
        workers: set[int] = set()

        def started() -> bool:
            assert parent.poll() is None, "compare ended before its workers started"
            workers.update(_children(parent.pid))
            return len(workers) >= 3  # 2 workers + the tracker

        wait_until(started, 90, "compare did not start its 2 workers")
        # both cells are training: each wrote its run's config.json when its training began
        cells = [
            tmp_path / "runs" / "2u1o" / m / "seed0" / "config.json" for m in ("remarl", "coma")
        ]
        wait_until(lambda: all(c.exists() for c in cells), 90, "the cells did not start training")
        parent.send_signal(signal.SIGINT)  # the parent only: it must stop its workers itself
        _, err = parent.communicate(timeout=30)
    assert parent.returncode == 130, err
    assert "run the same command to resume" in err and "Traceback" not in err
    wait_until(
        lambda: not any(os.path.exists(f"/proc/{w}") for w in workers),
        10,
        "a worker outlived compare",
    )
    assert not list(tmp_path.glob("runs/*/*/*/result.json"))  # nothing finished, nothing faked
