"""The shared-database contract: schema, migrations, table names and Zenoh key expressions.

``schema.sql`` is the single source of truth for tables; ``CONTRACT.md`` documents it in
language-neutral terms; ``keys`` holds every table name and key expression used in code.
"""
