"""Which command2robot images the relay may act on (CONTRACT.md, "Forged images").

An image is held to command2robot's rules (common.contract.tables, through
common.images.ImageGuard: the decision's velocities are a recommendation's, bounded; ids from
a sequence; the robot of its key; the recommendation it cites among those it considered),
and its id to what the table can hold: more than :data:`ID_HORIZON` beyond the newest id the
relay has read from the table, no sequence got there yet. An image that fails is counted
(``Counters.images_refused``), logged once per period, and the table is read instead.

An image inside every rule may still name a row the table never had (put with the
decision's own identity): the relay's next read finds the robot's newest row older than the
command it sent from the image, which :meth:`CommandImages.phantom` says, so the relay stops
holding the decision's own rows back behind the forged id.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Mapping
from typing import Any

from common.bus import Notification
from common.contract import keys
from common.images import ImageGuard

# The most command2robot rows the decision can have committed since the relay's last read of
# the table (it reads every command_period_s, 50 ms by default): thousands of times what 50
# robots re-issued at 10 Hz commit meanwhile. An image whose id is further ahead names a row
# no sequence gave yet: read the table.
ID_HORIZON = 100_000


class CommandImages:
    """The relay's judgement of command2robot images, and what the table has shown it."""

    def __init__(self, logger: logging.Logger, refused: Counter[str]) -> None:
        self.guard = ImageGuard(logger, refused=refused)
        self.newest_read = 0  # the highest command2robot id read from the table
        # per robot: the id of the last command sent from an image, and when it came
        self._sent: dict[str, tuple[int, float]] = {}

    def image(self, note: Notification) -> Mapping[str, Any] | None:
        """``note``'s image if the relay may act on it; None: read the table."""
        image = self.guard.image(note)  # None: none, or one the table's rules refuse
        if image is None:
            return None
        if note.id is not None and note.id > self.newest_read + ID_HORIZON:
            self.guard.refuse(
                keys.COMMAND2ROBOT,
                f"id {note.id} beyond the table's newest read ({self.newest_read}) + {ID_HORIZON}",
            )
            return None
        return image

    def sent(self, robot: str, row_id: int) -> None:
        """The command ``row_id`` was sent from its image (now)."""
        self._sent[robot] = (row_id, time.monotonic())

    def read(self, row_id: int) -> None:
        """A row ``row_id`` was read from the table."""
        if row_id > self.newest_read:
            self.newest_read = row_id

    def phantom(self, robot: str, newest_id: int, read_started: float) -> bool:
        """Whether the last command sent from an image of ``robot`` is one the table never
        had: a read that started after it came finds ``newest_id``, an older row (the writer
        commits before it notifies). Counted refused when so."""
        sent = self._sent.get(robot)
        if sent is None:
            return False
        if newest_id >= sent[0]:
            del self._sent[robot]  # the table has it
            return False
        if sent[1] > read_started:
            return False  # came during the read: the next read tells
        del self._sent[robot]
        self.guard.refuse(
            keys.COMMAND2ROBOT, f"command {sent[0]} sent from an image is not in the table"
        )
        return True
