"""`python -m pipeline`: the same CLI as the `pipeline` command."""

from pipeline.cli import main

main()
