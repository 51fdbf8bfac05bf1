"""The ``reachirl`` command line: parse, call the library, print.

Each subcommand lives in its own module of this package with ``add_parser(subparsers)`` and ``run(args) -> int``.
Exit codes: 0 success; 2 bad usage or bad input (one line naming the file and the problem); 1 internal error.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import signal
import sys

from ..errors import InputError

COMMANDS = ("reproduce", "synth", "preprocess", "fit", "evaluate", "plot", "simulate", "bench", "sensitivity")


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that every ``finally`` runs (workers ended, finished units kept)."""


def _on_sigterm(signum, frame):
    raise _Terminated()


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="reachirl", description="Learn human reaching costs with MO-IRL and predict reaches.")
    verbose_help = "log progress details to stderr, and show the traceback of an internal error"
    parser.add_argument("-v", "--verbose", action="store_true", help=verbose_help)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in COMMANDS:
        module = importlib.import_module(f"{__name__}.{name}")
        p = module.add_parser(sub)
        # -v anywhere on the line: SUPPRESS keeps the top-level value when the subcommand's flag is absent
        p.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help=verbose_help)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread (main() called from a thread): leave SIGTERM alone
        previous = None
    try:
        return _run(args)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _run(args) -> int:
    try:
        from ..doc.compiled import mode

        mode()  # a bad REACHIRL_COMPILE is an input error, before any work
        return int(args._run(args) or 0)
    except InputError as e:
        print(f"reachirl {args.command}: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # a path the user gave cannot be read or written (checked up front where possible)
        from ..validation import PATH_ERRNOS

        if args.verbose:
            raise
        if e.errno in PATH_ERRNOS:
            where = e.filename if e.filename is not None else "a file"
            print(f"reachirl {args.command}: error: {where}: {e.strerror or e}", file=sys.stderr)
            return 2
        print(f"reachirl {args.command}: internal error: {type(e).__name__}: {e} (rerun with -v for details)",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        terminated = isinstance(e, _Terminated)
        print(f"reachirl {args.command}: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
        return 143 if terminated else 130
    except Exception as e:  # an internal error: say so in one line; -v for the traceback
        if args.verbose:
            raise
        print(f"reachirl {args.command}: internal error: {type(e).__name__}: {e} (rerun with -v for details)",
              file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
