"""The services: each a separate process that imports ``common`` and never another service."""
