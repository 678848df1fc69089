"""Types of the extension module ftcbf._ftcbf (the Rust half of the package)."""

from __future__ import annotations

import os
import pathlib
from typing import Any, Callable, Optional, Protocol, Sequence, Union

import numpy as np
import numpy.typing as npt

CONTROLLERS: list[str]

class Error(Exception):
    """An error of ftcbf; the message is what the ``ftcbf`` command prints after ``error: ``."""

class WorldError(Error):
    """An invalid world file: the message names the file, the key or line, and what was
    expected."""

class ControlLawError(Error):
    """A control law written in Python raised (its exception is the ``__cause__``) or returned
    something that is not an input (a_x, a_y)."""

class World:
    """A world file, loaded and validated, with any overrides applied."""

    @staticmethod
    def load(
        path: Union[str, os.PathLike[str]], overrides: Optional[dict[str, float]] = None
    ) -> World: ...
    @property
    def name(self) -> str: ...
    @property
    def path(self) -> pathlib.Path: ...
    @property
    def seed(self) -> int: ...
    @property
    def duration(self) -> float: ...
    @property
    def control_dt(self) -> float: ...
    @property
    def controller(self) -> str: ...
    @property
    def overrides(self) -> dict[str, float]: ...
    def check(self, rollouts: int = 6) -> dict[str, Any]:
        """``ftcbf check`` as data: ``hypotheses`` (name, status, detail), ``filters``,
        ``goal``, ``theorem3`` (applies, epsilon, reasons, assumptions, horizon, line),
        ``liveness`` (live, line, cases, fix, ``rollouts``, …), ``condition_4_4`` per barrier,
        ``context`` and ``text`` (the report as printed). In a world with movers the liveness
        verdict is ``rollouts`` runs of the closed loop (``ftcbf check --rollouts``; 0: the
        search past the movers alone)."""

class LawConfig:
    """What a Python control law is built from."""

    channels: list[str]
    c: npt.NDArray[np.float64]
    goal: npt.NDArray[np.float64]
    goal_radius: float
    input_limit: Optional[npt.NDArray[np.float64]]
    dt: float
    fault_patterns: list[list[int]]
    barriers: list[str]
    seed: int

class Readings:
    """The readings of one control step, after any attack."""

    t: float
    dt: float
    y: npt.NDArray[np.float64]
    fresh: npt.NDArray[np.bool_]
    applied: Optional[npt.NDArray[np.float64]]

class ControlLaw(Protocol):
    """What a law factory returns: ``step(readings) -> (a_x, a_y)`` [m/s², world frame]."""

    def step(self, readings: Readings) -> Sequence[float] | npt.NDArray[np.float64]: ...

LawFactory = Callable[[LawConfig], ControlLaw]

class Frame:
    """One control step."""

    t: float
    step: int
    truth: dict[str, float]
    received: npt.NDArray[np.float64]
    clean: npt.NDArray[np.float64]
    fresh: npt.NDArray[np.bool_]
    rejected: npt.NDArray[np.bool_]
    detector_z: npt.NDArray[np.float64]
    estimates: npt.NDArray[np.float64]
    residues: npt.NDArray[np.float64]
    clf: npt.NDArray[np.float64]
    h: npt.NDArray[np.float64]
    h_true: npt.NDArray[np.float64]
    u: npt.NDArray[np.float64]
    command: npt.NDArray[np.float64]
    stage: str
    note: str
    attacks_active: npt.NDArray[np.bool_]
    events: list[str]

class Simulation:
    """One closed-loop run of a world."""

    def __init__(
        self,
        world: World,
        seed: Optional[int] = None,
        controller: Union[str, LawFactory, None] = None,
        duration: Optional[float] = None,
    ) -> None: ...
    def step(self) -> Optional[Frame]: ...
    def run(self) -> dict[str, Any]: ...
    def summary(self) -> dict[str, Any]: ...
    def record(self, path: Union[str, os.PathLike[str]]) -> None: ...
    @property
    def controller(self) -> str: ...
    @property
    def seed(self) -> int: ...
    @property
    def progress(self) -> tuple[int, int]: ...
    @property
    def sensors(self) -> list[str]: ...
    @property
    def filters(self) -> list[str]: ...
    @property
    def barriers(self) -> list[str]: ...
    @property
    def attacks(self) -> list[str]: ...

def batch(
    world: World,
    trials: int = 100,
    controllers: Optional[list[Union[str, LawFactory]]] = None,
    jobs: Optional[int] = None,
    seed: Optional[int] = None,
    sweep: Optional[str] = None,
    shard: Optional[str] = None,
) -> tuple[str, str]: ...
