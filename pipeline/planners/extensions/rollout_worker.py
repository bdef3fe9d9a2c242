"""A second process for a lookahead's rollouts, so that a decision uses both cores of the CPU.

A lookahead decision rolls out up to 16 gated-greedy episodes (4 candidates on each of 4
drawn maps), and they are independent. `RolloutWorker` is forked from the planner's process
at the first lookahead of an episode, so it already holds that episode's lattice geometry and
block index; each decision then sends it only what changes: the graph's state, the planner's
visits and gate verdicts, the observation and the drawn block maps, about 0.2 MB.

Both processes then take rollouts from one shared counter until none is left, so neither
waits while the other has work: `guide` starts its greedy candidates' rollouts before its own
denoising and the worker runs them meanwhile. Every rollout is the same computation in either
process, so the costs, and the routes, are those of one process.

Forking needs POSIX (`os.fork`); elsewhere `RolloutWorker.available()` is False and the
lookahead runs its rollouts in one process.
"""

from __future__ import annotations

import gc
import multiprocessing
import os
import traceback
from multiprocessing.connection import Connection, Pipe
from typing import TYPE_CHECKING, Callable

import numpy as np

from pipeline.lattice.graph import LatticeGraph
from pipeline.planners.baselines.frontier import GreedyUtilityPlanner
from pipeline.world.planner import Observation

if TYPE_CHECKING:
    from pipeline.world.simulator import Episode

#: (a job's context, the job's index in its batch) -> the job's rollout cost
RunJob = Callable[["JobContext", list[int], int], float]


class JobContext:
    """What one decision's rollouts read: the rollout planner, the observation, the known-graph
    predecessors from the robot and the drawn block maps; each process sets up a map's world once."""

    def __init__(self, planner, observation: Observation, pred: np.ndarray, drawn: list[np.ndarray]):
        self.planner, self.observation, self.pred, self.drawn = planner, observation, pred, drawn
        # map index -> that map's start and its exit distances (per process)
        self.worlds: dict[int, tuple[Episode, np.ndarray | None]] = {}


def take_jobs(counter, count: int, run: Callable[[int], float]) -> dict[int, float]:
    """Run jobs 0..count-1 that no other process has taken (one shared counter); {job: cost}."""
    done: dict[int, float] = {}
    while True:
        with counter.get_lock():
            job = counter.value
            if job >= count:
                return done
            counter.value = job + 1
        done[job] = run(job)


class RolloutWorker:
    """A forked process that takes rollout jobs from the counter it shares with its parent."""

    @staticmethod
    def available() -> bool:
        return hasattr(os, "fork")

    def __init__(self, run_job: RunJob, planner, state_names: tuple[str, ...]):
        """Fork now: the child keeps `run_job` (bound to its lookahead) and `planner`'s lattice.
        `state_names`: the attributes of the rollout planner that each decision sends (its graph
        goes as `LatticeGraph.state()`); the child runs them as a `GreedyUtilityPlanner`."""
        if not self.available():
            raise RuntimeError("a rollout worker needs os.fork (POSIX)")
        self.spec, self.state_names = planner.graph.spec, tuple(name for name in state_names if name != "graph")
        self.counter = multiprocessing.Value("q", 0)
        self.pending = False  # a batch was sent and its answer not yet received
        parent_end, child_end = Pipe()
        # Python's advice for a fork without exec: leave the objects alive now (the models, the
        # lattice: half a million) out of every later cyclic collection. A full collection walked
        # them for about 0.3 s, in the middle of a decision, and in the child it would copy the
        # pages it touched.
        gc.freeze()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child; its work is checked through the parent's answers
            status = 0
            try:
                parent_end.close()
                _serve(child_end, run_job, planner.graph, self.counter)
            except BaseException:  # noqa: BLE001 - a child must never return into the parent's code
                status = 1
            finally:
                os._exit(status)
        child_end.close()
        self.connection: Connection | None  # None once closed
        self.pid, self.connection = pid, parent_end

    def start(self, context: JobContext, candidates: list[int]) -> None:
        """A decision's first batch: its context and the jobs of `candidates` on every drawn map."""
        planner = context.planner
        view = {name: getattr(planner, name) for name in self.state_names}
        self._send(
            (
                "start",
                self.spec,
                planner.graph.state(),
                view,
                context.observation,
                context.pred,
                context.drawn,
                candidates,
            )
        )

    def more(self, candidates: list[int]) -> None:
        """Another batch on the same decision's context."""
        self._send(("more", candidates))

    def _send(self, message) -> None:
        if self.pending:  # a decision that failed before collecting its rollouts: drop the stale answer
            self.receive()
        self.counter.value = 0  # the worker is idle between batches: nothing races this reset
        assert self.connection is not None
        self.connection.send(message)
        self.pending = True

    def take(self, count: int, run: Callable[[int], float]) -> dict[int, float]:
        """The parent's share of the current batch."""
        return take_jobs(self.counter, count, run)

    def receive(self) -> dict[int, float]:
        """The worker's share of the current batch (RuntimeError on its failure, EOFError when gone)."""
        assert self.connection is not None
        kind, payload = self.connection.recv()
        self.pending = False
        if kind == "error":
            raise RuntimeError(f"rollout worker failed:\n{payload}")
        return payload

    def close(self) -> None:
        """Stop the worker (it exits at the end of its pipe) and reap it."""
        if self.connection is None:
            return
        try:
            self.connection.close()
        finally:
            self.connection = None
            try:
                os.waitpid(self.pid, 0)
            except ChildProcessError:
                pass

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass


def _serve(
    connection: Connection, run_job: RunJob, template: LatticeGraph, counter
) -> None:  # pragma: no cover - child

    context: JobContext | None = None
    while True:
        try:
            message = connection.recv()
        except (EOFError, OSError):
            return  # the parent closed the pipe or is gone
        try:
            if message[0] == "start":
                _, spec, graph_state, view, observation, pred, drawn, candidates = message
                if spec != template.spec:
                    raise ValueError("the planner's lattice changed without a new worker")
                planner = GreedyUtilityPlanner.__new__(GreedyUtilityPlanner)
                planner.__dict__.update(view)
                planner.graph = template.with_state(graph_state)
                context = JobContext(planner, observation, pred, drawn)
            else:
                candidates = message[1]
            assert context is not None  # a decision's "start" comes before its "more"
            count = len(context.drawn) * len(candidates)
            answer: tuple[str, dict[int, float] | str] = (
                "costs",
                take_jobs(counter, count, lambda job: run_job(context, candidates, job)),
            )
        except Exception:  # noqa: BLE001 - reported to the parent, which raises it
            answer = ("error", traceback.format_exc())
        connection.send(answer)
