"""pfp-service: real-time potential-field path planning for manned-unmanned teams."""

__version__ = "0.1.0"
__all__ = ["__version__"]
