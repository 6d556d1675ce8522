"""pfp_clients: the programs that talk to a planner over Zenoh (fleet, handheld, inject, demo).

They live in ``clients/pfp_clients`` and import as ``pfp_clients``.
"""
