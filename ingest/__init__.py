"""Readers of lab files (QTM TSV 3D/6D, C3D, QTM MAT, force logs, ATI .cal) and the MCAP I/O."""
