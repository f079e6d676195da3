"""A held sim (``--held``, services/sim/hold.py) on a real Zenoh router: it stands at sim time
0, steps to the ``until`` of a ``pnav/sim/run`` message and stands there, runs on when told
``until: nil``, and ignores a malformed message."""

from __future__ import annotations

import msgpack
import pytest

from common.bus import pack
from common.config import ZenohSettings
from common.contract import keys
from tests.contract.sim.test_sim_contract import DT, Listener, listener, running_sim

pytestmark = pytest.mark.timeout(60)
__all__ = ["listener"]  # the fixture, shared

ODOM = keys.robot_key("r1", keys.ODOM)
BATTERY = keys.robot_key("r1", keys.BATTERY_MSG)


def clocks_after(listener: Listener, n: int, more: int) -> list[dict[str, float]]:
    """The clock messages from the ``n``-th on, once ``more`` of them came."""
    listener.wait(lambda: len(listener.of(keys.SIM_CLOCK)) >= n + more)
    return list(listener.of(keys.SIM_CLOCK)[n:])


def test_a_held_sim_stands_at_zero_then_steps_exactly_as_far_as_it_is_let(
    zenoh_settings: ZenohSettings, listener: Listener
) -> None:
    with running_sim(zenoh_settings, rate=20.0, held=True):
        # held at 0: its clock stands still (rate 0, nothing to extrapolate), no reading
        stood = clocks_after(listener, 0, 10)
        assert {(c["stamp"], c["rate"]) for c in stood} == {(0.0, 0.0)}
        assert listener.of(ODOM) == [] and listener.of(BATTERY) == []

        # bad messages change nothing
        for bad in (pack({"until": -1.0}), pack({"until": True}), pack([1.0]), b"\xc1"):
            listener.session.put(keys.SIM_RUN, bad)
        n = len(listener.of(keys.SIM_CLOCK))
        assert {c["stamp"] for c in clocks_after(listener, n, 10)} == {0.0}

        listener.session.put(keys.SIM_RUN, pack({"until": 0.5}))
        listener.wait(lambda: [c for c in listener.of(keys.SIM_CLOCK) if c["stamp"] >= 0.5])
        n = len(listener.of(keys.SIM_CLOCK))
        held = clocks_after(listener, n, 10)
        # at the first step at or after 0.5 s, and there it stands
        assert {c["rate"] for c in held} == {0.0}
        (stamp,) = {c["stamp"] for c in held}
        assert 0.5 <= stamp < 0.5 + DT, stamp
        odoms = listener.of(ODOM)
        assert odoms and max(o["stamp"] for o in odoms) <= stamp
        battery = listener.of(BATTERY)[-1]

        listener.session.put(keys.SIM_RUN, msgpack.packb({"until": None}))
        on = listener.wait(lambda: [c for c in listener.of(keys.SIM_CLOCK) if c["stamp"] > 2.0])
        assert on[-1]["rate"] == 20.0
        drained = listener.wait(lambda: [b for b in listener.of(BATTERY) if b["stamp"] > 1.5])
        assert drained[0]["energy_wh"] < battery["energy_wh"]  # the battery drains again
