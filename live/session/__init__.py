"""``pipeline live``: a lab session recorded from QTM's real-time stream and watched as it
arrives: the capture held against ``session.toml``, every frame journalled, the tip and tare
calibrated, the presses and their states taken as they end, the recording a person watches."""
