"""The `pipeline` CLI and the stage code that turns phantom sessions into trained models."""

__version__ = "0.1.0"
