"""Imports point one way, and the flight path never imports torch."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def imported_modules(package: str) -> set[tuple[str, str]]:
    found = set()
    for path in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {(str(path), a.name.split(".")[0]) for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                found.add((str(path), node.module.split(".")[0]))
    return found


@pytest.mark.parametrize(
    ("package", "forbidden"),
    [("sim", {"torch", "remarl_fc", "policies"}), ("policies", {"remarl_fc"})],
)
def test_imports_point_one_way(package, forbidden):
    bad = sorted(f"{p}: {m}" for p, m in imported_modules(package) if m in forbidden)
    assert not bad, bad


def test_cli_and_sim_import_without_torch():
    code = (
        "import sys; import remarl_fc.cli, remarl_fc.offline.plots, remarl_fc.bench.sim, sim, sim.reward; "
        "import remarl_fc.policy_io, remarl_fc.offline.evaluate, remarl_fc.offline.rollout, sim.env; "
        "assert 'torch' not in sys.modules and 'policies' not in sys.modules"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_sitl_runs_with_torch_unimportable(tmp_path):
    """`remarl-fc sitl`, the flight runtime and the MAVLink layer work without torch."""
    code = (
        "import sys, importlib.abc\n"
        "class Block(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name.split('.')[0] == 'torch':\n"
        "            raise ImportError('blocked: ' + name)\n"
        "sys.meta_path.insert(0, Block())\n"
        "import remarl_fc.sitl.fleet, remarl_fc.bench.sitl, remarl_fc.mavlink.udp\n"
        "import remarl_fc.flight.runtime, remarl_fc.demo, remarl_fc.flight.flightlog, remarl_fc.bench.fly\n"
        "from remarl_fc.policy_io import load_policy; load_policy('3u2o')\n"
        "assert 'policies' not in sys.modules\n"
        "from remarl_fc.cli import main\n"
        "raise SystemExit(main(['sitl', '--scenario', '3u1o', '--base-port', '0',\n"
        "                       '--speedup', '50', '--timeout', '1', '--json']))\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=tmp_path, capture_output=True)
