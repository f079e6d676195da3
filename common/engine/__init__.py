"""The Proactive Engine (thesis section 3.2): five-step rules run from two FIFO queues."""

from common.engine.behaviour import Behaviour
from common.engine.engine import Engine
from common.engine.rule import Rule, Tests
from common.engine.stats import RuleStats
from common.engine.supervisor import Supervisor

__all__ = ["Behaviour", "Engine", "Rule", "RuleStats", "Supervisor", "Tests"]
