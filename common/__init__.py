"""What every proactive-nav service may import: the contract, the engine and the plumbing.

Services import ``common`` and third-party packages, never each other.
"""
