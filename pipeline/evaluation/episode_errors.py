"""A benchmark's planner that raises fails its episode, not the run.

`guide benchmark` (and the team benchmark, and the stages that run them) wraps each episode's
planner in `ErrorsEndTheEpisode`: an exception from its `reset` or `plan` is kept, the planner
says it has nothing more to do (an empty plan), and the episode ends there with its trajectory so
far; the benchmark records it as a failure `planner error: <type>: <message>` with the
traceback (`pipeline/evaluation/benchmark.py`). Everything else that runs episodes (the
simulator, the data collectors, the teachers) lets exceptions through as they are.
"""

from __future__ import annotations

import traceback
from typing import Any

from pipeline.planners.wrapper import PlannerWrapper

PLANNER_ERROR = "planner error"  # the failure's start when the planner raised


def planner_error(error: BaseException) -> str:
    """A planner's exception as an episode's failure: one line, PLANNER_ERROR, its type and message."""
    return f"{PLANNER_ERROR}: {type(error).__name__}: {' '.join(str(error).split())}"


class ErrorsEndTheEpisode(PlannerWrapper):
    """`inner` (a single-robot or a team planner), whose exception ends the episode: `error` holds
    its failure line and `error_traceback` its traceback ("" while it has not raised)."""

    def __init__(self, inner: Any):
        super().__init__(inner)
        self.error, self.error_traceback = "", ""

    def reset(self, *args: Any) -> None:  # a planner's (frame, protocol, seed), a team's (..., robots)
        self.error, self.error_traceback = "", ""
        try:
            self.inner.reset(*args)
        except Exception as error:  # noqa: BLE001 - any failure of the planner is the episode's
            self._keep(error)

    def plan(self, observation: Any) -> list:
        if self.error:
            return []
        try:
            return self.inner.plan(observation)
        except Exception as error:  # noqa: BLE001 - recorded, the episode ends with its trajectory so far
            self._keep(error)
            return []

    def _keep(self, error: BaseException) -> None:
        self.error, self.error_traceback = planner_error(error), traceback.format_exc()
