"""``python -m workbench``: the desktop window without arguments, the command line with them."""

from __future__ import annotations

import sys


def _main() -> int:
    if len(sys.argv) == 1:
        from workbench.cli.gui_cmd import launch

        return launch([])
    from workbench.cli.main import main

    return main()


if __name__ == "__main__":
    sys.exit(_main())
