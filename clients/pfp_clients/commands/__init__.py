"""The ``pfp`` subcommands that run a client: fleet, inject, demo and handheld.

Each module defines ``register(subparsers)`` as ``pfp_service.cli``'s own
commands do, and is listed in ``pyproject.toml`` under the
``pfp_service.commands`` entry-point group; that is how ``pfp`` finds them
without ``pfp_service`` importing this package.
"""

COMMANDS = ("demo", "fleet", "handheld", "inject")
