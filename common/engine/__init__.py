"""The Proactive Engine (thesis section 3.2): five-step rules run from two FIFO queues."""

from common.engine.engine import Engine
from common.engine.rule import Rule, Tests
from common.engine.stats import RuleStats
from common.engine.supervisor import Supervised, Supervisor, Ticket

__all__ = ["Engine", "Rule", "RuleStats", "Supervised", "Supervisor", "Tests", "Ticket"]
