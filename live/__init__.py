"""Live sessions: QTM's real-time stream recorded and watched as it arrives (``pipeline
live``), and a replay server that speaks QTM's real-time protocol (``pipeline replay``)."""
