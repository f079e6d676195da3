"""The dashboard: a browser view of every robot, a foreign client of the contract; GET /metrics."""
