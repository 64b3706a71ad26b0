"""QTM's real-time protocol: where a server is, its packets (the wire format, encoded and
decoded in one place), the commands a client sends, the parameters document it answers with,
and the client ``pipeline live`` connects with."""
