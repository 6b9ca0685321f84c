"""A real mosquitto broker on 127.0.0.1, started and stopped by the tests that need one."""

from __future__ import annotations

import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT_OK = "user root\n"
"""Run as root, mosquitto would switch to user "mosquitto", who cannot read pytest's tmp dirs;
as any other user the option is ignored."""

BROKER_START_S = 10.0
"""How long a broker may take to accept connections."""


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class Broker:
    """A mosquitto process on 127.0.0.1:port (restartable on the same port)."""

    port: int
    config: Path
    proc: subprocess.Popen[bytes] | None = None
    log: list[str] = field(default_factory=list)

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def start(self) -> None:
        exe = shutil.which("mosquitto") or "/usr/sbin/mosquitto"
        log = self.config.with_suffix(".log")
        with log.open("ab") as err:
            self.proc = subprocess.Popen([exe, "-c", str(self.config)], stdout=err, stderr=err)
        end = time.monotonic() + BROKER_START_S
        while time.monotonic() < end:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", self.port)) == 0:
                    return
            if self.proc.poll() is not None:
                raise RuntimeError(f"mosquitto exited: {log.read_text()}")
            time.sleep(0.05)
        raise RuntimeError("mosquitto did not start")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(timeout=10)
        self.proc = None


@contextmanager
def running_broker(folder: Path, *, anonymous: bool, extra_config: str = "") -> Iterator[Broker]:
    """A broker on a free loopback port, configured in folder, stopped on exit."""
    port = free_tcp_port()
    conf = folder / "mosquitto.conf"
    conf.write_text(
        f"listener {port} 127.0.0.1\nallow_anonymous {str(anonymous).lower()}\n"
        f"persistence false\n{ROOT_OK}{extra_config}"
    )
    broker = Broker(port, conf)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()


@pytest.fixture
def mosquitto(tmp_path: Path) -> Iterator[Broker]:
    """An anonymous broker on a free port, loopback only."""
    with running_broker(tmp_path, anonymous=True) as broker:
        yield broker


@pytest.fixture
def secured_mosquitto(tmp_path: Path) -> Iterator[Broker]:
    """A broker with passwords and per-vehicle ACLs: user N (a system id) with password "pw-N"
    may publish only under remarl/SWARM/uav/N/."""
    passwd = tmp_path / "passwd"
    exe = shutil.which("mosquitto_passwd") or "/usr/bin/mosquitto_passwd"
    for n in (1, 2, 3):
        args = [exe, "-b", str(passwd), str(n), f"pw-{n}"]
        if n == 1:
            args.insert(1, "-c")
        subprocess.run(args, check=True, capture_output=True)
    acl = tmp_path / "acl"
    acl.write_text("pattern read remarl/+/uav/+/+\npattern write remarl/+/uav/%u/+\n")
    extra = f"password_file {passwd}\nacl_file {acl}\n"
    with running_broker(tmp_path, anonymous=False, extra_config=extra) as broker:
        yield broker
