"""Live sessions over QTM's real-time protocol, by job: ``protocol/`` (the wire format, the
commands, the parameters document, the client), ``session/`` (``pipeline live``) and
``replay/`` (``pipeline replay``)."""
