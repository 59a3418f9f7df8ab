"""belt-tracker: poses of parts on a conveyor belt from one fixed camera."""

__version__ = "0.1.0"
