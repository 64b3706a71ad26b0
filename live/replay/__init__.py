"""``pipeline replay``: a recorded session served over QTM's real-time protocol, for live work
without a QTM."""
