"""Imports point one way between packages and between the rooms of `remarl_fc`; the flight path
never imports torch."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

FOUNDATIONS = {"errors", "frames", "resource", "policy_io", "_version"}
"""`remarl_fc` modules every room may use."""

ROOMS: dict[str, set[str]] = {
    # room: the other rooms (and top-level packages) it may import; see remarl_fc/__init__.py
    "errors": {"sim"},
    "frames": set(),
    "resource": set(),
    "_version": set(),
    "policy_io": {"errors", "sim"},
    "mavlink": {"errors", "resource"},
    "bus": {"errors", "resource"},
    "flight": {"mavlink", "bus", "sim"} | FOUNDATIONS,
    "sitl": {"mavlink", "sim"} | FOUNDATIONS,
    "offline": {"flight", "sim"} | FOUNDATIONS,
    "demo": {"flight", "sitl", "mavlink", "bus", "sim"} | FOUNDATIONS,
    "bench": {"flight", "sitl", "mavlink", "bus", "demo", "offline", "sim"} | FOUNDATIONS,
    "cli": {"flight", "sitl", "mavlink", "bus", "demo", "offline", "bench", "sim", "policies"}
    | FOUNDATIONS,
    "__init__": {"_version"},
    "__main__": {"cli"},
}

FLIGHT_PATH = ("mavlink", "bus", "flight", "sitl", "demo", "policy_io", "frames", "errors")
"""What `fly`, `sitl` and `demo` run: never torch, never `policies`."""


def imported_modules(package: str) -> set[tuple[str, str]]:
    found = set()
    for path in (ROOT / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {(str(path), a.name.split(".")[0]) for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                found.add((str(path), node.module.split(".")[0]))
    return found


def room_imports() -> set[tuple[str, str, str]]:
    """(file, its room, the room or package it imports), lazy imports inside functions too."""
    found = set()
    base = ROOT / "remarl_fc"
    for path in base.rglob("*.py"):
        parts = path.relative_to(base).parts
        room = parts[0] if len(parts) > 1 else parts[0].removesuffix(".py")
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            for name in names:
                top, _, rest = name.partition(".")
                if top == "remarl_fc" and rest:
                    target = rest.split(".")[0]
                elif top in ("sim", "policies", "torch"):
                    target = top
                else:
                    continue
                if target != room:
                    found.add((str(path.relative_to(ROOT)), room, target))
    return found


@pytest.mark.parametrize(
    ("package", "forbidden"),
    [("sim", {"torch", "remarl_fc", "policies"}), ("policies", {"remarl_fc"})],
)
def test_imports_point_one_way(package, forbidden):
    bad = sorted(f"{p}: {m}" for p, m in imported_modules(package) if m in forbidden)
    assert not bad, bad


def test_every_room_imports_only_the_rooms_it_may():
    found = room_imports()
    rooms = {room for _, room, _ in found}
    assert rooms <= set(ROOMS), f"new room(s) {rooms - set(ROOMS)}: add them to ROOMS"
    bad = sorted(
        f"{p} ({room} → {target})" for p, room, target in found if target not in ROOMS[room]
    )
    assert not bad, bad


def test_the_flight_path_never_imports_torch_or_policies():
    bad = sorted(
        f"{p}: {target}"
        for p, room, target in room_imports()
        if room in FLIGHT_PATH and target in ("torch", "policies")
    )
    assert not bad, bad


def test_cli_and_sim_import_without_torch():
    code = (
        "import sys; import remarl_fc.cli, remarl_fc.offline.plots, remarl_fc.bench.sim; "
        "import sim, sim.reward, sim.env; "
        "import remarl_fc.policy_io, remarl_fc.offline.evaluate, remarl_fc.offline.rollout; "
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
        "import remarl_fc.flight.runtime, remarl_fc.flight.flightlog, remarl_fc.flight.core\n"
        "import remarl_fc.demo, remarl_fc.bench.fly\n"
        "from remarl_fc.policy_io import load_policy; load_policy('3u2o')\n"
        "assert 'policies' not in sys.modules\n"
        "from remarl_fc.cli import main\n"
        "raise SystemExit(main(['sitl', '--scenario', '3u1o', '--base-port', '0',\n"
        "                       '--speedup', '50', '--timeout', '1', '--json']))\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=tmp_path, capture_output=True)
