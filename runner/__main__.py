"""`python -m runner` is the `dynsplines` command."""
from runner.cli import main

raise SystemExit(main())
