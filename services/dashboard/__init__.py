"""The dashboard: a browser view of every robot, and a foreign client of the contract."""
