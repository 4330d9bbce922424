"""`python -m runner.fig10 [KEYFRAMES.json] [--out FILE.png]`: figure 10 of the paper (runner/commands/fig10.py)."""
from runner.commands.fig10 import main

if __name__ == "__main__":
    raise SystemExit(main())
