"""The `mesp` console: one sub-command per module in ``mesp_cell.commands``.

A user's mistake (``InputError``, a malformed option, a file the system will not let us read
or write) prints one line ``mesp: error: <problem>; <fix>`` and exits 2; an interrupted
command exits 130; nothing else is swallowed.
"""

from __future__ import annotations

import sys

if sys.argv[1:2] == ["estop"] and __name__ != "__main__":  # `mesp estop`: the stop first
    from mesp_cell.estop_socket import fast_estop

    _code = fast_estop(sys.argv[2:])
    if _code is not None:
        sys.exit(_code)

# the rest only after the e-stop's dispatch above: the stop waits for no import
import argparse
import importlib
import pkgutil
import typing
from collections.abc import Sequence

from core.errors import InputError


def command_modules() -> list[str]:
    """Names of the sub-command modules: each has ``register(subparsers)`` setting ``func``."""
    import mesp_cell.commands as package

    return sorted(m.name for m in pkgutil.iter_modules(package.__path__) if not m.ispkg)


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one ``mesp: error: ...; <fix>`` line (exit 2)."""

    def error(self, message: str) -> typing.NoReturn:
        text = " ".join(message.split())
        print(f"mesp: error: {text}; see `{self.prog} --help`", file=sys.stderr)
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser, with every registered sub-command."""
    parser = OneLineParser(
        prog="mesp",
        description="MESP Cell: multi-axis embedded silicone printing with a UR5e.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in command_modules():
        module = importlib.import_module(f"mesp_cell.commands.{name}")
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `mesp` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["estop"]:  # the stop must not wait for every command to be imported
        from mesp_cell.estop_socket import fast_estop

        code = fast_estop(argv[1:])
        if code is not None:
            return code
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except InputError as exc:
        print(f"mesp: error: {exc.one_line()}", file=sys.stderr)
        return 2
    except OSError as exc:  # a path the system refuses: permissions, a full disk, a device
        where = f" ({exc.filename})" if exc.filename else ""
        print(f"mesp: error: {exc.strerror or exc}{where}; check the path, its permissions "
              "and the free space", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("mesp: interrupted", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":
    sys.exit(main())
