"""EpisodeRecorder: an episode's frames drawn as it runs, written as a GIF and a final PNG."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from pipeline.lattice.frontier import frontier_mask
from pipeline.lattice.graph import LatticeGraph
from pipeline.reporting.render import episode_title, render_frame, save_gif
from pipeline.world.simulator import Episode


class EpisodeRecorder:
    """An `on_step` callback for `run_episode` that renders a frame every `every` steps.

    At most `max_frames` frames are kept: when there would be more, every other frame is
    dropped and the stride doubles, so the kept frames stay evenly spaced. The episode's
    final state is always the last frame (rendered when `frames`/`save_gif` is asked for).
    `graph_provider` (e.g. `lambda: innermost(planner).graph`) supplies the planner's graph, if any;
    frontier cells are recomputed from the current belief, since the planner's graph is
    only brought up to date at its next decision.
    """

    def __init__(
        self,
        every: int = 1,
        max_frames: int = 150,
        graph_provider: Callable[[], "LatticeGraph | None"] | None = None,
        scale: int = 2,
        label: str = "",
        legend: bool = True,
        y_up: bool = False,
    ):
        if every < 1:
            raise ValueError("every must be at least 1")
        if max_frames < 2:
            raise ValueError("max_frames must be at least 2")
        self.every = int(every)
        self.max_frames = int(max_frames)
        self.graph_provider = graph_provider
        self.scale = int(scale)
        self.label = label
        self.legend = legend
        self.y_up = y_up
        self.reset()

    def reset(self) -> None:
        self._frames: list[np.ndarray] = []
        self._steps: list[int] = []
        self._stride = self.every
        self._episode: "Episode | None" = None
        self._last_step = -1
        self._final: tuple[int, np.ndarray] | None = None

    def __call__(self, episode: Episode) -> None:
        if self._episode is not None and episode is not self._episode:
            self.reset()
        self._episode = episode
        step = episode.steps
        if step == self._last_step:
            return
        self._last_step = step
        self._final = None
        if step % self._stride:
            return
        self._frames.append(self.render(episode))
        self._steps.append(step)
        if len(self._frames) > self.max_frames - 1:  # one place stays free for the final frame
            self._frames = self._frames[::2]
            self._steps = self._steps[::2]
            self._stride *= 2

    def render(self, episode: Episode) -> np.ndarray:
        """A frame of the episode as it is now."""
        graph = self.graph_provider() if self.graph_provider is not None else None
        belief = episode.belief.grid.copy()
        trajectory = list(episode.trajectory)
        min_unknown = graph.spec.frontier_min_unknown_neighbours if graph is not None else 2
        title = episode_title(
            episode.map.name,
            self.label,
            episode.distance,
            episode.steps,
            episode.explored_ratio,
            True if episode.complete else None,
        )
        return render_frame(
            episode.map,
            belief,
            trajectory,
            graph,
            self.scale,
            title,
            frontier=frontier_mask(belief, min_unknown),
            legend=self.legend,
            y_up=self.y_up,
        )

    @property
    def steps(self) -> list[int]:
        """The episode step of each frame in `frames`."""
        self._finish()
        return list(self._steps) + ([self._final[0]] if self._final is not None else [])

    @property
    def frames(self) -> list[np.ndarray]:
        """The frames so far, the episode's latest state last."""
        self._finish()
        return list(self._frames) + ([self._final[1]] if self._final is not None else [])

    def _finish(self) -> None:
        if self._episode is None or self._final is not None:
            return
        if self._steps and self._steps[-1] == self._last_step:
            return
        self._final = (self._last_step, self.render(self._episode))

    def save_gif(self, path: str | Path, fps: float = 8, hold_last_s: float = 2.0) -> Path:
        """Write the frames as an animated GIF that loops forever and holds the last frame."""
        return save_gif(self.frames, path, fps=fps, hold_last_s=hold_last_s)
