"""Entry point of the frozen workbench (the PyInstaller bundle's executable).

``workbench`` with arguments is the command line, without arguments the
desktop window (as ``python -m workbench``).

A frozen app has no Python interpreter to start ``python -m MODULE`` with:
its ``sys.executable`` is this program.  The window's helper process
(:mod:`workbench.core.helper_process`) is started as ``sys.executable -m
workbench.core.helper_process``, so that one form is recognised here and run
as the module it names; any other ``-m`` is refused.
"""

from __future__ import annotations

import runpy
import sys

#: modules a frozen ``workbench -m MODULE`` may run (only the helper process)
RUNNABLE_MODULES = ("workbench.core.helper_process",)


def main() -> int:
    args = sys.argv[1:]
    if args[:1] == ["-m"]:
        module = args[1] if len(args) > 1 else ""
        if module not in RUNNABLE_MODULES:
            print(f"workbench: -m {module}: not available in the bundled app", file=sys.stderr)
            return 64
        sys.argv = [sys.argv[0], *args[2:]]
        runpy.run_module(module, run_name="__main__", alter_sys=True)
        return 0
    from workbench.__main__ import _main

    return _main()


if __name__ == "__main__":
    sys.exit(main())
