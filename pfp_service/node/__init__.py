"""The planner's I/O: the Zenoh node, its rings and writes, the durable store, the worker pools,
configuration and logging. It drives the sans-I/O world (``pfp_service.world``) and decides nothing
the world can decide.
"""
