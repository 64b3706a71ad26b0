"""``pipeline ingest`` and ``pipeline inspect``: the lab's files read, checked and stored.

The readers (QTM TSV 3D/6D/analog, C3D, QTM MAT, force logs, the mocap's analog channels,
ATI .cal; :mod:`ingest.detect` tells them apart) and the MCAP I/O; the ingest stage runner
(:mod:`ingest.ingest_stage`), its settings (:mod:`ingest.ingest_params`) and its view
(:mod:`ingest.ingest_view`); the inspect runner
(:mod:`ingest.inspect_stage`, per format: :mod:`ingest.inspect_lab`,
:mod:`ingest.inspect_outputs`) and its text view (:mod:`ingest.inspect_view`), beside the
readers whose knowledge it uses.
"""
