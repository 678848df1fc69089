"""ftcbf from Python: world files, ``ftcbf check``'s verdict, the closed-loop simulator with the
paper's FT-CBF-CLF controller (or a control law written in Python), and the Monte Carlo safety
certification of ``ftcbf batch``.

The numbers are the Rust libraries' own: a run's ``summary()`` is ``ftcbf run --json``'s, and
``batch()`` returns what ``ftcbf batch`` prints and writes.
"""

from __future__ import annotations

import json
import os
from typing import Any, Callable, Iterable, Optional, Sequence, Union

from ._ftcbf import (
    CONTROLLERS,
    ControlLawError,
    Error,
    Frame,
    LawConfig,
    Readings,
    Simulation,
    World,
    WorldError,
)
from ._ftcbf import batch as _batch

__all__ = [
    "CONTROLLERS",
    "BatchResult",
    "ControlLawError",
    "Error",
    "Frame",
    "LawConfig",
    "Readings",
    "Simulation",
    "World",
    "WorldError",
    "batch",
]

Controller = Union[str, Callable[[LawConfig], Any]]


class BatchResult:
    """The result of ``batch()``: ``results`` holds one dict per sweep point (one without a
    sweep) exactly as ``ftcbf batch --out FILE.json`` writes it (``plan``, ``summaries`` per
    controller with the safe rate, its Clopper–Pearson interval and verdict, ``paired`` McNemar
    comparisons, every trial's ``records``); ``report`` is the text the command prints;
    ``json`` is the file's text."""

    def __init__(self, json_text: str, report: str) -> None:
        self.json = json_text
        self.report = report
        data = json.loads(json_text)
        self.format: str = data["format"]
        self.results: list[dict[str, Any]] = data["results"]

    def summary(self, controller: str, point: int = 0) -> dict[str, Any]:
        """The summary of ``controller`` (a built-in name or a Python law's name) at sweep
        point ``point``."""
        for s in self.results[point]["summaries"]:
            if s["controller"] == controller:
                return s
        names = [s["controller"] for s in self.results[point]["summaries"]]
        raise KeyError(f"no controller `{controller}` in this batch (it ran {', '.join(names)})")

    def write(self, path: Union[str, os.PathLike]) -> None:
        """Writes the JSON file ``ftcbf batch --out FILE.json`` would (the input of
        ``ftcbf merge``)."""
        with open(path, "w", encoding="utf-8") as f:
            f.write(self.json)

    def __str__(self) -> str:
        return self.report

    def __repr__(self) -> str:
        points = len(self.results)
        names = [s["controller"] for s in self.results[0]["summaries"]]
        return f"BatchResult(world={self.results[0]['plan']['world']!r}, controllers={names}, points={points})"


def batch(
    world: Union[World, str, os.PathLike],
    trials: int = 100,
    controllers: Sequence[Controller] = ("ft-cbf-clf", "baseline"),
    jobs: Optional[int] = None,
    seed: Optional[int] = None,
    sweep: Optional[str] = None,
    shard: Optional[str] = None,
) -> BatchResult:
    """``ftcbf batch``: ``trials`` independent trials of ``world``, every controller on the
    same trial seeds, exact 95 % Clopper–Pearson intervals against the world's claim, the exact
    McNemar test between the first controller and each other one.

    ``controllers`` holds built-in names and Python law factories (see ``Simulation``);
    ``jobs``: worker threads (None: one per core); ``seed``: base seed (None: the world's);
    ``sweep``: ``"KEY=V1,V2,..."`` (one batch per value); ``shard``: ``"K/N"``. A ``World``
    loaded with overrides runs with them. The GIL is released while the trials run (a Python
    law takes it back for each of its steps)."""
    if not isinstance(world, World):
        world = World.load(world)
    text, report = _batch(world, trials, list(controllers), jobs, seed, sweep, shard)
    return BatchResult(text, report)
