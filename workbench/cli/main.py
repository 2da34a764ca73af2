"""Entry point of the ``workbench`` command.

Every sub-command is a thin wrapper over a service or an io function, so the
same work can be scripted from Python.  Errors a user can act on
(:class:`~workbench.core.errors.WorkbenchError`) are printed as one clear
line and exit with status 2; anything unexpected prints a short message
(``--debug`` shows the traceback) and exits with status 1.  A command whose
skull registration asks for a check (``reconstruct``, ``landmarks suggest``,
``template build``) writes its outputs, says why first, and exits with status 3.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

import workbench
from workbench.cli import (
    age_cmd,
    animate_cmd,
    batch_cmd,
    case_cmd,
    compare_cmd,
    gui_cmd,
    ct_cmd,
    demo_cmd,
    fit_scan_cmd,
    landmarks_cmd,
    mesh_cmd,
    reconstruct_cmd,
    samples_cmd,
    template_cmd,
    validate_cmd,
)
from workbench.core.errors import WorkbenchError

_MODULES = (
    demo_cmd,
    ct_cmd,
    mesh_cmd,
    landmarks_cmd,
    case_cmd,
    template_cmd,
    fit_scan_cmd,
    samples_cmd,
    compare_cmd,
    reconstruct_cmd,
    validate_cmd,
    animate_cmd,
    age_cmd,
    batch_cmd,
    gui_cmd,
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="workbench",
        description=(
            "Forensic and anthropometry workbench: CT and mesh import, skull and skin "
            "landmarks, tissue-depth reconstruction and growth simulation. All geometry "
            "is in millimetres."
        ),
    )
    parser.add_argument("--version", action="version", version=f"workbench {workbench.__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show full tracebacks for unexpected errors"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in _MODULES:
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "handler", None):
        parser.print_help()
        return 0
    try:
        return int(args.handler(args) or 0)
    except BrokenPipeError:
        # the reader went away (``workbench samples list | head``): a normal end; stdout
        # is pointed at devnull so the interpreter's final flush does not fail again
        import os

        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except WorkbenchError as exc:
        print(f"workbench {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        # a file the command could not read or write (a folder where a file is
        # expected, no permission, disk full): name the path and the problem
        if exc.filename is None or args.debug:
            return _unexpected(args, exc)
        where = f"{exc.filename}" + (f" -> {exc.filename2}" if exc.filename2 else "")
        print(
            f"workbench {args.command}: error: {where}: cannot be read or written "
            f"({exc.strerror or exc})",
            file=sys.stderr,
        )
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - last resort: never a bare traceback for users
        return _unexpected(args, exc)


def _unexpected(args: argparse.Namespace, exc: Exception) -> int:
    if args.debug:
        raise exc
    print(
        f"workbench {args.command}: unexpected error: {type(exc).__name__}: {exc}\n"
        "(rerun with --debug for the full traceback, and please report it)",
        file=sys.stderr,
    )
    return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
