"""`remarl-fc compare --quick`: the grid runs, resumes, and writes well-formed outputs."""

from __future__ import annotations

import csv
import json

import pytest

from remarl_fc.cli import main

pytestmark = pytest.mark.timeout(180)


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
    assert [r["method"] for r in rows] == ["e2coop", "remarl"]
    assert float(rows[0]["paper_reaction_ms"]) == 480.0
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
    from pathlib import Path

    from policies.compare import CompareConfig, _episode_counts

    cfg = CompareConfig(("3u2o",), ("remarl", "mappo", "e2coop"), out=Path("unused"))
    results = [
        {"method": "remarl", "episodes": 200.0},
        {"method": "mappo", "episodes": 100.0},
        {"method": "mappo", "episodes": 200.0},
    ]
    assert _episode_counts(cfg, results) == "remarl 200, mappo 100–200"


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
    import os
    import signal
    import subprocess
    import sys
    import time

    with subprocess.Popen(
        [sys.executable, "-c", ORPHAN_SCRIPT], stdout=subprocess.PIPE, text=True
    ) as parent:
        assert parent.stdout is not None
        worker = int(parent.stdout.readline())
        os.kill(worker, 0)  # alive, busy with its cell
        parent.send_signal(signal.SIGKILL)
        parent.wait(10)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            os.kill(worker, 0)
        except ProcessLookupError:
            return
        time.sleep(0.2)
    os.kill(worker, signal.SIGKILL)
    pytest.fail("the worker outlived its compare process by 15 s")


def _children(pid: int) -> set[int]:
    """Process ids whose parent is ``pid`` (from /proc)."""
    from pathlib import Path

    kids = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue  # gone meanwhile
        if int(fields[1]) == pid:
            kids.add(int(stat.parent.name))
    return kids


def test_ctrl_c_stops_the_workers_at_once_and_says_how_to_resume(tmp_path):
    import os
    import signal
    import subprocess
    import sys
    import time

    args = ["compare", "--scenarios", "2u1o", "--methods", "remarl,coma", "--seeds", "1"]
    args += ["--budget", "1000000", "--workers", "2", "--out", str(tmp_path)]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    with subprocess.Popen(
        [sys.executable, "-m", "remarl_fc", *args], stderr=subprocess.PIPE, text=True, env=env
    ) as parent:
        deadline = time.monotonic() + 90
        while len(workers := _children(parent.pid)) < 3:  # 2 workers + the tracker
            assert time.monotonic() < deadline and parent.poll() is None, "no workers started"
            time.sleep(0.2)
        time.sleep(2.0)  # the cells are training
        parent.send_signal(signal.SIGINT)  # the parent only: it must stop its workers itself
        _, err = parent.communicate(timeout=30)
    assert parent.returncode == 130, err
    assert "run the same command to resume" in err and "Traceback" not in err
    deadline = time.monotonic() + 10
    while any(os.path.exists(f"/proc/{w}") for w in workers):
        assert time.monotonic() < deadline, "a worker outlived compare"
        time.sleep(0.2)
    assert not list(tmp_path.glob("runs/*/*/*/result.json"))  # nothing finished, nothing faked
