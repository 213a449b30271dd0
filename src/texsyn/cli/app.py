"""The ``texsyn`` command line: the group, the entry point, exit statuses and messages.

Exit status (``docs/errors.md``):

- 0: success.
- 1: a failure that is not the user's mistake: an output could not be written (disk full,
  permission denied), the machine ran out of memory, a system error, or an internal error
  (a bug: one line, ``--debug`` shows the traceback).
- 2: bad input: a usage error or any :class:`texsyn.errors.InputError` (missing or
  unreadable file, bad size or value, unknown method or parameter, output that exists,
  names an input, or lies in a missing or read-only folder, work too large for memory).
- 130: interrupted (SIGINT, Ctrl-C); 143: terminated (SIGTERM).
- 141: the reader of the output left (``texsyn methods | head -1``): like a program that
  SIGPIPE ends, texsyn stops quietly, without a message.

Every error prints one line ``texsyn: error: ...`` on stderr, every warning one line
``texsyn: warning: ...`` (a deprecated parameter name among them). Outputs are written all
or none through :class:`texsyn.io.OutputSet`: nothing is created or replaced on any failure.

This module holds the ``texsyn`` group, the entry point and the mapping of every outcome to
one line and an exit status; the commands are in :mod:`~texsyn.cli.synthesis`,
:mod:`~texsyn.cli.modification`, :mod:`~texsyn.cli.animation`, :mod:`~texsyn.cli.editing`,
:mod:`~texsyn.cli.comparison` and :mod:`~texsyn.cli.listing`, each imported when its command
runs (:data:`COMMANDS`).
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
import threading
import traceback
import warnings
from typing import Any, NoReturn

import click

from .._lazy import lazy_exports
from .._version import __version__
from ..errors import InputError, OutputWriteError
from .common import State

__all__ = [
    "COMMANDS",
    "EXIT_BAD_INPUT",
    "EXIT_BROKEN_PIPE",
    "EXIT_FAILURE",
    "EXIT_INTERRUPTED",
    "EXIT_OK",
    "EXIT_TERMINATED",
    "Terminated",
    "cli",
    "exit_process",
    "main",
    "report_error",
    "run",
]

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE


class Terminated(BaseException):
    """SIGTERM arrived. Raised in the main thread (like ``KeyboardInterrupt`` for SIGINT) so
    that every ``finally``/``except BaseException`` cleanup runs and no temporary is left."""


# ---------------------------------------------------------------------------- the group
#: each command and the name of its function, in the order ``texsyn --help`` lists them
COMMANDS = {
    "synth": "synth",
    "replay": "replay_command",
    "modify": "modify",
    "animate": "animate",
    "fill": "fill_command",
    "transfer": "transfer_command",
    "compare": "compare",
    "batch": "batch",
    "serve": "serve",
    "methods": "list_methods",
}

#: loads a command's function from the module of this package that defines it
_command_function, _ = lazy_exports(
    __package__ or "",
    {
        "synth": "synthesis",
        "replay_command": "replaying",
        "modify": "modification",
        "animate": "animation",
        "fill_command": "editing",
        "transfer_command": "editing",
        "compare": "comparison",
        "batch": "batch",
        "serve": "serving",
        "list_methods": "listing",
    },
)


class LazyCommands(click.Group):
    """A group whose commands are imported when invoked (or listed by ``--help``).

    ``texsyn synth -m quilting`` then loads the ``synth`` command and the quilting method
    only, not ``animate``'s grouplets or ``compare``'s metrics (``docs/performance.md``,
    "Start-up").
    """

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        function = COMMANDS.get(cmd_name)
        if function is None:
            return None
        command: click.Command = _command_function(function)
        return command


def _set_debug(ctx: click.Context, param, value: bool) -> None:
    if value:
        ctx.ensure_object(State).debug = True


def _set_progress(ctx: click.Context, param, value: str) -> None:
    ctx.ensure_object(State).progress = value


@click.group(cls=LazyCommands, context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--debug",
    is_flag=True,
    is_eager=True,
    expose_value=False,
    callback=_set_debug,
    help="Print the full traceback of an error (also TEXSYN_DEBUG=1).",
)
@click.option(
    "--progress",
    type=click.Choice(["bar", "json"]),
    default="bar",
    show_default=True,
    is_eager=True,
    expose_value=False,
    callback=_set_progress,
    help="How commands report progress on stderr: a bar, or one JSON object per line "
    '({"progress": {"stage", "done", "total"}}) for another program to read.',
)
@click.version_option(__version__, "--version", prog_name="texsyn", message="%(prog)s %(version)s")
def cli() -> None:
    """Exemplar-based texture synthesis.

    Outputs are written all or none; an existing file is kept unless --overwrite, and an
    output never replaces an input. Each command also writes a JSON sidecar
    (OUTPUT.json: method, parameters, seed, inputs, version, command line).

    \b
    Exit status: 0 done; 1 failure that is not your input (write error, out of memory,
    internal error); 2 bad input or usage; 130 interrupted; 143 terminated.
    """


# ---------------------------------------------------------------------------- entry point
def _one_line(text: str, limit: int = 400) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _describe_os_error(exc: OSError) -> str:
    if exc.filename and exc.strerror:
        return f"{exc.strerror}: '{exc.filename}'"
    return str(exc) or type(exc).__name__


#: the signals the handlers of :func:`_install_signal_handlers` received in this process
_RECEIVED: list[int] = []


def _signal_behind(exc: BaseException) -> BaseException:
    """The signal's exception when ``exc`` is what the signal caused, not a failure of its own.

    A signal handler that raises while a compiled (numba) function runs leaves the exception
    set when the function returns, and the interpreter reports ``SystemError: ... returned a
    result with an exception set``, usually with the signal's exception as its cause or
    context, but not always (the function may run on a worker thread's behalf); so any error
    that ends a run after one of texsyn's handlers received a signal is that signal's.
    """
    chained: BaseException | None = exc
    for _ in range(16):  # the chain of causes and contexts
        if chained is None:
            break
        if isinstance(chained, (KeyboardInterrupt, Terminated)):
            return chained
        chained = chained.__cause__ or chained.__context__
    if _RECEIVED:
        return Terminated() if _RECEIVED[0] == signal.SIGTERM else KeyboardInterrupt()
    return exc


def report_error(exc: BaseException, state: State) -> int:
    """One line on stderr for ``exc`` (the traceback first with --debug); the exit status."""
    if state.debug:
        traceback.print_exception(exc, file=sys.stderr)

    def say(line: str) -> None:
        sys.stderr.write(line.rstrip() + "\n")
        sys.stderr.flush()

    if isinstance(exc, BrokenPipeError):  # nobody reads any more: nothing to say
        _silence_closed_streams()
        return EXIT_BROKEN_PIPE
    exc = _signal_behind(exc)
    if isinstance(exc, Terminated):
        say("texsyn: terminated")
        return EXIT_TERMINATED
    if isinstance(exc, (KeyboardInterrupt, click.exceptions.Abort)):
        say("texsyn: interrupted")
        return EXIT_INTERRUPTED
    if isinstance(exc, click.ClickException):
        say(f"texsyn: error: {_one_line(exc.format_message())}")
        return EXIT_BAD_INPUT
    if isinstance(exc, InputError):
        say(f"texsyn: error: {_one_line(str(exc) or type(exc).__name__)}")
        return EXIT_BAD_INPUT
    if isinstance(exc, OutputWriteError):
        say(f"texsyn: error: {_one_line(str(exc))}")
        return EXIT_FAILURE
    if isinstance(exc, MemoryError):
        say(
            "texsyn: error: out of memory; request a smaller output or a smaller exemplar "
            "(TEXSYN_MEMORY_LIMIT sets how much texsyn may plan to use)"
        )
        return EXIT_FAILURE
    if isinstance(exc, OSError):
        say(f"texsyn: error: {_one_line(_describe_os_error(exc))}")
        return EXIT_FAILURE
    if isinstance(exc, SystemExit):
        return exc.code if isinstance(exc.code, int) else EXIT_FAILURE
    hint = "" if state.debug else " (run with --debug for the traceback)"
    say(f"texsyn: internal error: {type(exc).__name__}: {_one_line(str(exc), 300)}{hint}")
    return EXIT_FAILURE


def _silence_closed_streams() -> None:
    """Point a standard stream whose reader left at ``/dev/null``.

    Python flushes ``stdout`` and ``stderr`` at exit; what is left for a closed pipe would
    print ``Exception ignored ... BrokenPipeError`` (the Python documentation's recipe,
    ``signal`` module, "Note on SIGPIPE").
    """
    for stream in (sys.stdout, sys.stderr):
        if stream is None:  # pragma: no cover - started without the stream
            continue
        try:
            stream.flush()
        except OSError:
            try:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, stream.fileno())
                os.close(devnull)
            except (OSError, ValueError):  # pragma: no cover - a stream without a descriptor
                pass


def _show_warning(message, category, filename, lineno, file=None, line=None):
    sys.stderr.write(f"texsyn: warning: {_one_line(message)}\n")


def _install_signal_handlers():
    """SIGINT -> KeyboardInterrupt, SIGTERM -> Terminated, once; return a function restoring the old handlers.

    After the first signal both are ignored, so that a second one cannot interrupt the
    removal of temporary files. Signals a parent asked to ignore stay ignored.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    _RECEIVED.clear()
    previous: dict[int, Any] = {}

    def handler(signum, frame):
        _RECEIVED.append(signum)
        for sig in previous:
            signal.signal(sig, signal.SIG_IGN)
        if signum == signal.SIGTERM:
            raise Terminated()
        raise KeyboardInterrupt()

    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            old = signal.getsignal(sig)
            if old is signal.SIG_IGN:
                continue
            signal.signal(sig, handler)
            previous[sig] = old
        except (ValueError, OSError):  # pragma: no cover - platforms without the signal
            pass

    def restore() -> None:
        for sig, old in previous.items():
            signal.signal(sig, old if old is not None else signal.SIG_DFL)

    return restore


def _env_flag(name: str) -> bool:
    return os.environ.get(name, "").strip().lower() in ("1", "true", "yes", "on")


def _run(args: list[str], state: State) -> int:
    try:
        if not args:
            with click.Context(cli, info_name="texsyn") as ctx:
                click.echo(cli.get_help(ctx))
        else:
            with cli.make_context("texsyn", list(args), obj=state) as ctx:
                cli.invoke(ctx)
        if sys.stdout is not None:  # None: started with its descriptor closed (``>&-``)
            sys.stdout.flush()  # a closed pipe shows here, not at exit
        return EXIT_OK
    except click.exceptions.Exit as exc:
        return exc.exit_code
    except BaseException as exc:
        return report_error(exc, state)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``texsyn`` console script; returns the exit status."""
    args = list(sys.argv[1:] if argv is None else argv)
    state = State(debug=_env_flag("TEXSYN_DEBUG"), argv=[str(a) for a in args])
    with warnings.catch_warnings():
        warnings.showwarning = _show_warning
        # texsyn's own deprecations (an old parameter name) reach the user as one line
        warnings.filterwarnings("default", category=DeprecationWarning, module=r"texsyn(\.|$)")
        restore = _install_signal_handlers()
        try:
            try:
                return _run(state.argv, state)
            except Terminated:  # arrived while reporting another error
                return EXIT_TERMINATED
            except KeyboardInterrupt:
                return EXIT_INTERRUPTED
        finally:
            restore()


def run() -> NoReturn:
    """The ``texsyn`` console script and ``python -m texsyn.cli``: :func:`main`, then the end
    of the process (:func:`exit_process`)."""
    exit_process(main())


def exit_process(status: int) -> NoReturn:
    """End the process with ``status``: what Python's exit does first, without its teardown.

    At exit Python joins the threads that are not daemons, runs the :mod:`atexit`
    functions, flushes ``stdout`` and ``stderr``, then takes every module and object apart
    one by one: 20 ms to 0.2 s of a texsyn command, the most where numba is loaded
    (``docs/performance.md``, "Start-up"), for
    memory the system takes back at once when the process ends. This does the first three
    and ends the process there (:func:`os._exit`). Python's own exit (:func:`sys.exit`)
    runs instead where a thread other than texsyn's idle workers is still running, a
    debugger, profiler or coverage tracer is attached, ``python -i`` is to follow, or a
    stream cannot be flushed (a closed pipe: Python reports it as it always does).
    """
    linalg = sys.modules.get("texsyn.ops.linalg")  # the pool's module: loaded by every method, not by --help
    if linalg is not None:
        linalg.stop_thread_pool()
    current = threading.current_thread()
    running = [t for t in threading.enumerate() if t is not current and not t.daemon and t.is_alive()]
    run_exit_functions = getattr(atexit, "_run_exitfuncs", None)
    if (
        running
        or run_exit_functions is None
        or current is not threading.main_thread()
        or sys.gettrace() is not None
        or sys.getprofile() is not None
        or sys.flags.inspect
    ):
        sys.exit(status)
    try:
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                stream.flush()
        run_exit_functions()
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                stream.flush()
    except BaseException:
        sys.exit(status)
    os._exit(status)
