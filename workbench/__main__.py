"""``python -m workbench``: the command line (the desktop window will open from here once it exists)."""

from __future__ import annotations

import sys

from workbench.cli.main import main

if __name__ == "__main__":
    sys.exit(main())
