"""The ground layer: errors, atomic outputs, provenance, progress, units, text and JSON forms
of values, time-series containers and rerun helpers. Imports nothing of ours, so every
package can stand on it."""

__version__ = "0.1.0"
