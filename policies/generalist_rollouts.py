"""DAgger's rollouts flown in other processes while this one learns (``rollout_processes``).

A DAgger iteration (`policies.generalist_dagger`) is two halves of about equal length on one
core: flying every world of the mixture with the teacher labelling (the simulator and the
shield, numpy) and learning from the labels (torch). With ``rollout_processes`` = P > 0 the
worlds are split into P runs of about equal UAV counts, each flown by a process of its own
(`serve`), and the two halves overlap: while this process learns from rollout i, the others fly
rollout i + 1 with the actor as it was before that learning — one iteration behind, which
DAgger's aggregated labels do not mind (every state is labelled by the teacher, whoever flew
it). On this 2-core machine P = 1 does a 20-minute round's iterations in about 13 minutes:
the learner, whose steps slow when the other core is busy too, becomes the longer half.

Each process builds the run's worlds as `RunBook.open` does (the same draw of which families
fly the real world, the same first episodes) and keeps its own run of them; requests carry the
actor's weights and β, answers a `DaggerRollout`. A request's random stream is
(seed, 2, process, request), so a run with the same settings flies the same rollouts. The
runs' states stay in the processes: after a DAgger phase shorter than the run
(``dagger_fraction`` < 1), PPO goes on from the worlds' first episodes, with new ones drawn
after those the processes drew.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from numpy.typing import NDArray

from policies.config import GeneralistConfig
from policies.generalist_dagger import DaggerRollout, fly_dagger
from sim.errors import WorkerFailed
from sim.observation import ObservationLayout

if TYPE_CHECKING:
    from policies.generalist_train import RunBook

POLL_S = 1.0
"""Seconds between checks that a silent rollout process is still alive."""

JOIN_S = 10.0
"""Seconds a rollout process is given to stop when asked, before it is terminated."""

Weights = dict[str, NDArray[np.float32]]
"""A network's state as numpy arrays: what travels between the processes."""


def numpy_state(module: torch.nn.Module) -> Weights:
    """``module``'s state dict as numpy arrays on the CPU."""
    return {k: v.detach().cpu().numpy() for k, v in module.state_dict().items()}


@dataclass(frozen=True)
class FleetSpec:
    """What a rollout process needs to build its run of worlds.

    Attributes:
        cfg: the run's settings. layout: its observation. goal_value: the arrival's value.
        index: the process's number. first, stop: its run of worlds, ``worlds[first:stop]``
        of `make_worlds`. drawn: per world of it, the episodes drawn so far (a resumed run's).
        anchor: the "self-shield" teacher's proposer's weights, or None for a state teacher.
    """

    cfg: GeneralistConfig
    layout: ObservationLayout
    goal_value: float
    index: int
    first: int
    stop: int
    drawn: tuple[int, ...]
    anchor: Weights | None


def split_worlds(uavs: list[int], parts: int) -> list[tuple[int, int]]:
    """``parts`` contiguous runs (first, stop) of worlds with about equal UAV counts each.

    ``uavs``: each world's UAVs (environments × N). Every run holds at least one world; no
    more runs than worlds.
    """
    parts = max(1, min(parts, len(uavs)))
    cumulative = np.cumsum(uavs)
    cuts = [0]
    for p in range(1, parts):
        cut = int(np.searchsorted(cumulative, cumulative[-1] * p / parts)) + 1
        cuts.append(min(max(cut, cuts[-1] + 1), len(uavs) - (parts - p)))
    return list(zip(cuts, [*cuts[1:], len(uavs)], strict=True))


def serve(conn: Connection, spec: FleetSpec) -> None:
    """A rollout process: answer each request (weights, β, number) with a `DaggerRollout`.

    None asks it to stop. An exception is sent back as ("error", text) before it exits.
    """
    from policies.generalist import SetNet
    from policies.generalist_train import make_worlds, teach

    try:
        torch.set_num_threads(1)
        cfg = spec.cfg
        worlds = make_worlds(cfg, spec.layout, np.random.default_rng([cfg.seed, 1]))
        mine = worlds[spec.first : spec.stop]
        for world, drawn in zip(mine, spec.drawn, strict=True):
            world.drawn = drawn
        actor = SetNet(spec.layout, cfg.hidden, critic=False, pooling=cfg.pooling)
        anchor = None
        if spec.anchor is not None:
            anchor = SetNet(spec.layout, cfg.hidden, critic=False, pooling=cfg.pooling)
            anchor.load_state_dict({k: torch.from_numpy(v) for k, v in spec.anchor.items()})
            anchor.requires_grad_(False)

        def teacher(worlds: list[Any]) -> list[NDArray[np.float32]]:
            return teach(worlds, cfg, anchor, "cpu")

        while (request := conn.recv()) is not None:
            weights, beta, number = request
            actor.load_state_dict({k: torch.from_numpy(v) for k, v in weights.items()})
            rng = np.random.default_rng([cfg.seed, 2, spec.index, number])
            conn.send(fly_dagger(mine, actor, teacher, beta, cfg, spec.goal_value, rng, "cpu"))
    except BaseException as exc:  # every failure goes back to the learner, then ends this
        with contextlib.suppress(OSError):
            conn.send(("error", f"{exc!r}\n{traceback.format_exc()}"))
        raise
    finally:
        conn.close()


class RolloutFleet:
    """``processes`` rollout processes flying the run's worlds, one rollout ahead.

    A context manager: the processes start on entry and stop on any exit (asked first, then
    terminated). `fly` returns the next rollout and asks for the one after it.
    """

    def __init__(self, book: RunBook, processes: int) -> None:
        self.book = book
        uavs = [w.envs * w.cfg.uav.count for w in book.worlds]
        self.runs = split_worlds(uavs, processes)
        self.conns: list[Connection] = []
        self.procs: list[BaseProcess] = []
        self.requests = 0
        self.threads = torch.get_num_threads()

    def __enter__(self) -> RolloutFleet:
        book = self.book
        # the learner keeps the cores the rollout processes leave: torch's threads would
        # otherwise contend with them for every core (a round then ran 40 % slower)
        self.threads = torch.get_num_threads()
        spare = (os.cpu_count() or 1) - len(self.runs)
        torch.set_num_threads(max(1, min(self.threads, spare)))
        ctx = multiprocessing.get_context("spawn")
        anchor = numpy_state(book.anchor) if book.anchor is not None else None
        for index, (first, stop) in enumerate(self.runs):
            here, there = ctx.Pipe()
            spec = FleetSpec(
                book.cfg,
                book.layout,
                book.goal_value,
                index,
                first,
                stop,
                tuple(w.drawn for w in book.worlds[first:stop]),
                anchor,
            )
            proc = ctx.Process(
                target=serve, args=(there, spec), name=f"rollouts-{index}", daemon=True
            )
            proc.start()
            there.close()
            self.conns.append(here)
            self.procs.append(proc)
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        for conn in self.conns:
            with contextlib.suppress(OSError):  # already gone
                conn.send(None)
        for conn, proc in zip(self.conns, self.procs, strict=True):
            # the rollout still in flight is not wanted: read it away so the process can stop
            deadline = time.monotonic() + JOIN_S
            while proc.is_alive() and time.monotonic() < deadline:
                with contextlib.suppress(EOFError, OSError):
                    if conn.poll(0.1):
                        conn.recv()
            if proc.is_alive():
                proc.terminate()
            proc.join(JOIN_S)
            conn.close()
        torch.set_num_threads(self.threads)

    def fly(self, beta: Callable[[], float]) -> DaggerRollout:
        """The next rollout (waited for), after asking for the one after it.

        ``beta``: β now (each request is flown with the β of when it was sent). The first call
        asks for two, both with the actor as it is.
        """
        if self.requests == 0:
            self._request(beta())
        self._request(beta())
        parts = [self._receive(i, conn) for i, conn in enumerate(self.conns)]
        return DaggerRollout.merge(parts)

    def _request(self, beta: float) -> None:
        weights = numpy_state(self.book.nets.actor)
        for index, conn in enumerate(self.conns):
            try:
                conn.send((weights, beta, self.requests))
            except OSError as exc:
                raise self._stopped(index) from exc
        self.requests += 1

    def _stopped(self, index: int) -> WorkerFailed:
        proc = self.procs[index]
        proc.join(POLL_S)
        return WorkerFailed(
            f"rollout process {index} stopped (exit code {proc.exitcode}) without an answer: "
            "out of memory, or killed? Resume the run with --resume, with fewer "
            "--rollout-processes or none"
        )

    def _receive(self, index: int, conn: Connection) -> DaggerRollout:
        proc = self.procs[index]
        while not conn.poll(POLL_S):
            if not proc.is_alive():
                raise self._stopped(index)
        try:
            answer = conn.recv()
        except (EOFError, OSError) as exc:
            raise self._stopped(index) from exc
        if isinstance(answer, tuple):
            raise WorkerFailed(f"rollout process {index} failed: {answer[1]}")
        if not isinstance(answer, DaggerRollout):
            raise WorkerFailed(f"rollout process {index} answered {type(answer).__name__}")
        return answer
