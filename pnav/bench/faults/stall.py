"""The dwa-stall fault (``pnav bench faults``, kind ``stall``): r1 switched mid-mission to a
strategy row asking dwa for its heaviest decisions; the controller's engine_stats then say
its longest rule run and how often safety_stop ran meanwhile."""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING, Any

from common.contract import keys
from common.runtime import Runtime
from pnav.bench.faults.context import ROBOT, Context, Injection
from pnav.cli import stack_commands

if TYPE_CHECKING:
    from pnav.bench.faults.catalogue import Fault

# the hostile tester's strategy params (issue 28): 255,000 poses a decision as asked
DWA_STALL = {"dwa_steps": 50, "dwa_linear_samples": 50, "dwa_angular_samples": 100,
             "dwa_horizon_s": 10}  # fmt: skip
STALL_CODE = "DWA_STALL"

_STALL_STRATEGY = f"""
INSERT INTO {keys.STRATEGY} (code, planner_scenario, controller_scenarios, params, description)
SELECT $1, planner_scenario, controller_scenarios, params || $2::jsonb,
       'GOTO_FAST asking dwa for its heaviest decisions (pnav bench faults, dwa-stall)'
FROM {keys.STRATEGY} WHERE code = 'GOTO_FAST'
ON CONFLICT (code) DO NOTHING"""

_CONTROLLER_RULES = f"""
SELECT rule_type, sum(executed) AS executed, sum(acted) AS acted, max(max_time_s) AS max_s
FROM {keys.ENGINE_STATS} WHERE service = 'controller' GROUP BY rule_type"""


async def _controller_rules(rt: Runtime) -> dict[str, Any]:
    return {r["rule_type"]: r for r in await rt.database.pool.fetch(_CONTROLLER_RULES)}


async def stall(fault: Fault, ctx: Context) -> Injection:
    rt = ctx.rt
    await rt.database.write(keys.STRATEGY, None, _STALL_STRATEGY, STALL_CODE, DWA_STALL)
    before = await _controller_rules(rt)
    verdict, reason = await stack_commands.send_user_command(rt, ROBOT, "SET_STRATEGY", STALL_CODE)
    out = Injection(notes=[f"SET_STRATEGY {STALL_CODE}: {verdict} {reason}".strip()])
    # the mission drives on under it; engine_stats are written every 2 s (PNAV_STATS_PERIOD_S)
    await asyncio.sleep(fault.seconds)
    after = await _controller_rules(rt)
    if after:
        longest = max(after.values(), key=lambda r: r["max_s"])
        out.notes.append(
            f"controller's longest rule run: {longest['rule_type']} "
            f"{longest['max_s'] * 1e3:.1f} ms (rule budget 50 ms)"
        )
    stop, was = after.get("SafetyStop"), before.get("SafetyStop")
    ran = (stop["executed"] - (was["executed"] if was else 0)) if stop else 0
    acted = (stop["acted"] - (was["acted"] if was else 0)) if stop else 0
    out.notes.append(
        f"safety_stop ran {ran} times ({acted} recommendations) in the {fault.seconds:.0f} s"
        if ran
        else "safety_stop did NOT run during the stall"
    )
    return out
