"""The base of the learned controller scenarios (learned_drive, foresight): each reads the
planned path and the model its strategy names in acquisition, and stands down while that
model is refused.

A subclass sets ``params`` (the prefix of its strategy params: ``<params>_model``,
``<params>_model_version``, pnav_learned.registry) and ``kind`` (the model kind it loads),
and decides in :meth:`judge` with :meth:`model` and ``self.path``.
"""

from __future__ import annotations

from typing import Any, ClassVar

from common.contract.planned_path import PlannedPath
from common.controller_core.scenario import ControllerScenario
from pnav_learned.model import Kinds
from pnav_learned.registry import Found, resolve


class LearnedScenario(ControllerScenario):
    needs_odometry = True
    params: ClassVar[str]
    kind: ClassVar[Kinds]

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.path: PlannedPath | None = None
        self.found: Found | str = "not read yet"
        self.refusal: str | None = None  # why this scenario stands down, for tests and people

    async def data_acquisition(self) -> None:
        live = self.live
        self.path = await self.host.planned_path(self.spec.robot.robot_id) if live else None
        if live:
            self.found = await resolve(self.host, self.spec.params, self.params, self.kind)
        await super().data_acquisition()

    def model(self) -> Found | None:
        """The model to decide with; None (and ``refusal`` says why) while it is refused:
        the scenario stands down and the strategy's other scenarios drive."""
        found = self.found
        if isinstance(found, str):
            self.refusal = found
            return None
        self.refusal = None
        return found
