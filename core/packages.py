"""Our top-level packages, named once.

The demo's stage cache hashes their sources (a code change reruns its steps), and
``tests/test_layering.py`` gives each its layer and checks that this list and its own agree.
Packaging (setuptools) and import sorting (ruff) find them from the project root themselves.
"""

PACKAGES: tuple[str, ...] = ("core", "data_schema", "ingest", "calib", "sync", "extract",
                             "split", "sim", "train", "live", "pipeline")
