"""A second controller: plain SQL through asyncpg, Zenoh and msgpack, and nothing else.

It replaces ``services.controller`` with no change anywhere else, which is the point: the
shared-database contract (CONTRACT.md) is all a scenario service needs. See README.md.
"""
