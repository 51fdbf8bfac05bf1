"""The ``reachirl`` command line: parse, call the library, print.

Each subcommand lives in its own module of this package with ``add_parser(subparsers)`` and ``run(args) -> int``.
Exit codes: 0 success; 2 bad usage or bad input (one line naming the file and the problem); 1 internal error;
130 on Ctrl-C and 143 on SIGTERM, also when compiled code swallowed the interrupt (the signal is recorded, and
nothing is written after it); 141, silently, when standard output's reader closed it (``| head``).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import logging
import os
import re
import signal
import sys
import threading

from .. import errors
from ..errors import InputError, Terminated

COMMANDS = ("reproduce", "synth", "preprocess", "fit", "evaluate", "plot", "simulate", "bench", "sensitivity")
#: each command's line in ``reachirl --help`` and its parser's ``help``: listing the commands imports none of them
SUMMARIES = {
    "reproduce": "run the seed paper's protocol and write its table and figures",
    "synth": "write virtual subjects (Berret's protocol) with their true cost weights",
    "preprocess": "motion-capture files -> trials (q, qd, qdd, tau on the subject's planar arm)",
    "fit": "learn cost weights from demonstration trials",
    "evaluate": "predict every trial from its own start and report joint-angle RMSE",
    "plot": "draw predictions, weight shares and convergence as PNG and PDF",
    "simulate": "play predicted reaches back in MuJoCo and render them",
    "bench": "run the performance benchmarks and print their figures",
    "sensitivity": "occlusion, sensitivity and identifiability of a reproduce run's costs",
}


_Terminated = Terminated

#: seconds a command may take to stop after Ctrl-C or SIGTERM before it is ended outright, for compiled code that
#: swallows the interrupt and runs on (the solves of reachirl itself stop within a fraction of a second)
STOP_GRACE_S = 1.5
_watchdog: dict = {}
#: what a command asked to be done if it is ended outright (:func:`at_forced_exit`)
_at_forced_exit: list = []


def at_forced_exit(fn) -> None:
    """Call ``fn()`` (from the watchdog's thread, its errors ignored) if the command is ended outright
    :data:`STOP_GRACE_S` after a signal, just before the process exits: e.g. remove what its atomic writes had
    begun (a command stuck in compiled code never reaches its own cleanup)."""
    _at_forced_exit.append(fn)


def _arm_watchdog(command: str, signum: int) -> None:
    """On the first signal: end the process with 130/143 if the command has not stopped STOP_GRACE_S later
    (nothing is written meanwhile: every write checks for a signal first)."""
    if _watchdog.get("timer") is not None:
        return
    code = 143 if signum == signal.SIGTERM else 130

    def force_exit() -> None:
        io = sys.modules.get("reachirl.io")  # no import from this thread: a process that never wrote has none
        with contextlib.suppress(Exception):
            if io is not None:
                io.remove_pending_temporaries()  # the atomic writes in progress (an animation being encoded, ...)
        for fn in list(_at_forced_exit):
            with contextlib.suppress(Exception):
                fn()
        try:
            print(
                f"reachirl {command}: {'terminated' if code == 143 else 'interrupted'}", file=sys.__stderr__, flush=True
            )
        finally:
            os._exit(code)

    timer = threading.Timer(STOP_GRACE_S, force_exit)
    timer.daemon = True
    timer.start()
    _watchdog["timer"] = timer


def _on_sigterm(signum, frame):
    errors.note_signal(signum)
    raise Terminated()


def _on_sigint(signum, frame):
    errors.note_signal(signum)
    raise KeyboardInterrupt


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage error is one line, ``PROG: error: MESSAGE``, and exit 2 (argparse's own
    prints its usage first): the command line's, and the examples' (``examples/*.py``)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message}\n")


SIGNED_AXIS_OPTIONS = ("--up-axis", "--forward-axis")
"""Options whose value may start with '-' (``-z``), which argparse would otherwise read as an option."""


def _signed_axes(argv: list[str]) -> list[str]:
    """``--up-axis -z`` as ``--up-axis=-z`` (argparse refused it: 'expected one argument')."""
    out: list[str] = []
    for tok in argv:
        if out and out[-1] in SIGNED_AXIS_OPTIONS and re.fullmatch(r"-[xyzXYZ]", str(tok)):
            out[-1] = f"{out[-1]}={tok}"
        else:
            out.append(tok)
    return out


def build_parser(commands=COMMANDS) -> argparse.ArgumentParser:
    """The command line's parser, with the options of ``commands`` (each imports its module); the other commands
    are listed with their :data:`SUMMARIES` line only (``main`` builds the one command it runs: importing every
    command's module took a second before ``reachirl --help`` or any command)."""
    parser = OneLineParser(prog="reachirl", description="Learn human reaching costs with MO-IRL and predict reaches.")
    verbose_help = "log progress details to stderr, and show the traceback of an internal error"
    parser.add_argument("-v", "--verbose", action="store_true", help=verbose_help)
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    parser.commands = {}  # each command's parser: an unknown option is its error, named as its own
    for name in COMMANDS:
        if name not in commands:
            sub.add_parser(name, help=SUMMARIES[name])
            continue
        module = importlib.import_module(f"{__name__}.{name}")
        p = parser.commands[name] = module.add_parser(sub)
        # -v anywhere on the line: SUPPRESS keeps the top-level value when the subcommand's flag is absent
        p.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help=verbose_help)
        p.set_defaults(_run=module.run)
    return parser


def _catch_signals() -> dict:
    """The command line's SIGTERM and Ctrl-C handlers; returns the handlers they replace (none when ``main`` runs
    in another thread than the main one: the signals are then left alone)."""
    previous = {}
    try:
        previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, _on_sigterm)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # an ignored Ctrl-C stays ignored
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:
        pass
    return previous


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    # caught from the start: the commands' modules load for a second or two (scipy, CasADi), and a SIGTERM then
    # ended the process without a word
    previous = _catch_signals()
    try:
        try:
            argv = _signed_axes(sys.argv[1:] if argv is None else list(argv))
            named = next((a for a in argv if not a.startswith("-")), None)  # the only top-level option is a flag
            parser = build_parser((named,) if named in COMMANDS else ())
            args, unknown = parser.parse_known_args(argv)
        except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM (Terminated) while loading: nothing was done
            terminated = isinstance(e, Terminated)
            print(f"reachirl: {'terminated' if terminated else 'interrupted'}", file=sys.stderr, flush=True)
            return 143 if terminated else 130
        if unknown:  # "reachirl fit: error: ...", as the command's other errors say it
            parser.commands[args.command].error(f"unrecognized arguments: {' '.join(unknown)}")
        logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(message)s")
        errors.track_signals(bool(previous), lambda signum: _arm_watchdog(args.command, signum))
        return _run(args)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        errors.track_signals(False)
        timer = _watchdog.pop("timer", None)
        if timer is not None:
            timer.cancel()
        _at_forced_exit.clear()


def _interrupted(args, terminated: bool) -> int:
    word = "terminated" if terminated else "interrupted"
    print(f"reachirl {args.command}: {word}", file=errors.unmuted_stderr(), flush=True)
    return 143 if terminated else 130


def _run(args) -> int:
    try:
        code = _run_command(args)
    except (Exception, KeyboardInterrupt):
        # a signal swallowed by compiled code (a CasADi call returns a failed result, the next step fails): the
        # error is the interrupt's consequence; report the interrupt
        if errors.signalled() is None:
            raise
        code = 0
    if errors.signalled() is not None:
        return _interrupted(args, errors.signalled() == signal.SIGTERM)
    return code


def _run_command(args) -> int:
    try:
        from ..doc.compiled import mode

        mode()  # a bad REACHIRL_COMPILE is an input error, before any work
        return int(args._run(args) or 0)
    except InputError as e:
        if errors.signalled() is not None:
            raise
        print(f"reachirl {args.command}: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError as e:  # stdout's reader went away (`| head`): the rest of the output is not wanted
        if not _stdout_broken():
            return _internal_error(args, e)  # another pipe (a worker's): not the reader's choice
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # nor the interpreter's last flush
        os.close(devnull)
        return 141  # as a process ended by SIGPIPE: not a success
    except OSError as e:  # a path the user gave cannot be read or written (checked up front where possible)
        from ..validation import PATH_ERRNOS

        if args.verbose or errors.signalled() is not None:
            raise
        if e.errno in PATH_ERRNOS:
            where = e.filename if e.filename is not None else "a file"
            print(f"reachirl {args.command}: error: {where}: {e.strerror or e}", file=sys.stderr)
            return 2
        return _internal_error(args, e)
    except KeyboardInterrupt as e:
        if errors.signalled() is not None:
            raise
        return _interrupted(args, isinstance(e, Terminated))
    except Exception as e:  # an internal error: say so in one line; -v for the traceback
        return _internal_error(args, e)


def _internal_error(args, e: BaseException) -> int:
    if args.verbose or errors.signalled() is not None:
        raise e
    print(
        f"reachirl {args.command}: internal error: {type(e).__name__}: {e} (rerun with -v for details)",
        file=sys.stderr,
    )
    return 1


def _stdout_broken() -> bool:
    """Whether standard output is a pipe whose reader has gone (the poll reports an error on its end)."""
    import select

    try:
        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poll.poll(0))
    except (OSError, ValueError, AttributeError):  # no file descriptor (a test's capture), or no poll
        return False


if __name__ == "__main__":
    sys.exit(main())
