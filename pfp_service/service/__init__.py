"""The live planner service: configuration, the sans-I/O world model and the Zenoh node."""
