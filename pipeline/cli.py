"""What every command line does with a bad input: one line on stderr naming what is wrong, exit 2.

:func:`cli_main` runs a command's ``run(argv)``; a refused input or output (``ValueError``,
``KeyError``, ``FileExistsError``, ``OSError``, :class:`UsageError`) and argparse's own usage
errors end with exit status 2, an interruption with 128 + the signal's number (130 for Ctrl-C,
143 for SIGTERM), and never with a Python traceback. SIGTERM is turned into the same interruption as
Ctrl-C while the command runs, so that either leaves the outputs as they were: the temporary files
being written are removed on the way out and nothing is moved into place (a SIGKILL, which no
process sees, may leave a hidden temporary file, never a partial file under an output's name; the
next writer of that name removes it).
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading

from calib.noise import SensorNoise
from pipeline.formats import forget_created_folders, one_line, take_back_created_folders

__all__ = ["UsageError", "ArgumentParser", "cli_main", "one_line", "nonnegative_int", "positive_int",
           "EXIT_USAGE", "EXIT_INTERRUPTED", "Interrupted", "scheduler_address", "add_executor_arguments",
           "add_noise_arguments", "noise_from_arguments", "keep_freed_memory", "MALLOC_TRIM_THRESHOLD",
           "MALLOC_MMAP_MAX", "KEPT_FREED_BYTES"]

#: Exit status of a refused input, output or flag (argparse's own).
EXIT_USAGE = 2
#: Exit status of a run interrupted by Ctrl-C.
EXIT_INTERRUPTED = 130


#: glibc's ``mallopt`` parameter: free memory at the heap's top kept up to this many bytes.
MALLOC_TRIM_THRESHOLD = -1
#: glibc's ``mallopt`` parameter: most allocations served by their own ``mmap`` (0: none).
MALLOC_MMAP_MAX = -4
#: Freed memory a one-shot command keeps for its next arrays (:func:`keep_freed_memory`).
KEPT_FREED_BYTES = 2 ** 30


def keep_freed_memory() -> bool:
    """Let this process reuse the memory of its freed arrays instead of asking the kernel for
    fresh pages (glibc's ``mallopt``: no allocation by its own ``mmap``, up to
    :data:`KEPT_FREED_BYTES` of freed memory kept). A one-shot command on 100,000 rows makes
    and frees arrays of tens to hundreds of MB stage after stage; by default glibc serves each
    above 32 MB by ``mmap`` and returns it on ``free``, so every next one is fresh pages, zeroed
    by the kernel on first touch (on the 100,000-row hexapod recording: 174,000 page faults, 1.3
    s of system time; kept: 126,000, 0.7 s; peak memory 0.58 -> 0.63 GB). Only for a process
    that ends after its one run (the memory is kept until it exits). Returns whether it took
    effect (False off glibc)."""
    import ctypes

    try:
        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(MALLOC_MMAP_MAX, 0)) and bool(mallopt(MALLOC_TRIM_THRESHOLD, KEPT_FREED_BYTES))


class Interrupted(KeyboardInterrupt):
    """The command received a termination signal (``signum``) while it ran."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _interrupt(signum, frame) -> None:
    raise Interrupted(signum)


class UsageError(ValueError):
    """A command-line value is refused; the message names the flag."""


def cli_main(run, argv: list[str] | None = None) -> int:
    """``run(argv)``, with refusals turned into one line on stderr and exit status 2; a refused or
    interrupted command leaves no output folder it created (those still empty are removed)."""
    forget_created_folders()
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _interrupt) if main_thread else None
    try:
        run(argv)
    except SystemExit as exc:  # argparse: --help (0) or a usage error (2, already printed)
        take_back_created_folders()
        if isinstance(exc.code, str):
            print(f"error: {' '.join(exc.code.split())}", file=sys.stderr)
            return EXIT_USAGE
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    except KeyboardInterrupt as exc:
        take_back_created_folders()
        signum = exc.signum if isinstance(exc, Interrupted) else signal.SIGINT
        by = f" ({signal.Signals(signum).name})" if signum != signal.SIGINT else ""
        print(f"error: interrupted{by}; nothing was written", file=sys.stderr)
        return EXIT_INTERRUPTED - signal.SIGINT + signum
    except (ValueError, KeyError, FileExistsError, OSError) as exc:
        take_back_created_folders()
        print(f"error: {one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)
    forget_created_folders()
    return 0


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line on stderr (exit status 2)."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"error: {self.prog}: {' '.join(message.split())} (see --help)\n")


def _int_at_least(minimum: int, text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {text!r}") from None
    if value < minimum:
        raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {value}")
    return value


def nonnegative_int(text: str) -> int:
    """argparse type: an integer >= 0 (seeds, counts that may be zero)."""
    return _int_at_least(0, text)


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1 (counts that cannot be zero: seeds, workers, poses)."""
    return _int_at_least(1, text)


def scheduler_address(text: str) -> str:
    """argparse type: the address of a Dask scheduler (``tcp://host:8786``, ``host:8786``, ``tls://...``),
    checked for its form only (whether a scheduler answers there is found on connecting)."""
    from distributed.comm import get_address_host_port  # only when the flag is given

    try:
        get_address_host_port(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"not a Dask scheduler address: {exc}") from None
    return text


def add_executor_arguments(parser) -> None:
    """``--workers N`` and ``--scheduler ADDRESS`` (the executor of a many-task command)."""
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="processes of the local Dask cluster (default: all cores; 1: run here, "
                             "no cluster)")
    parser.add_argument("--scheduler", type=scheduler_address, default=None, metavar="ADDRESS",
                        help="run on an existing Dask cluster (e.g. tcp://host:8786) instead of a local one")


def add_noise_arguments(p: argparse.ArgumentParser) -> None:
    """``--noise-mm``, ``--noise-rad``, ``--noise-joint`` (Gaussian standard deviations; default
    :data:`pipeline.workflows.design.DEFAULT_NOISE`)."""
    from pipeline.workflows.design import DEFAULT_NOISE

    p.add_argument("--noise-mm", type=float, default=DEFAULT_NOISE.position_mm, help="position noise std, mm")
    p.add_argument("--noise-rad", type=float, default=DEFAULT_NOISE.orientation_rad,
                   help="angle noise std, rad (robots with angle coordinates)")
    p.add_argument("--noise-joint", type=float, default=DEFAULT_NOISE.joint,
                   help="joint-reading noise std, the robot's joint unit (default 0: exact joints)")


def noise_from_arguments(args) -> SensorNoise:
    """The Gaussian :class:`SensorNoise` of :func:`add_noise_arguments`' options."""
    try:
        return SensorNoise(args.noise_mm, args.noise_rad, "normal", args.noise_joint)
    except ValueError as exc:
        raise UsageError(f"--noise-mm/--noise-rad/--noise-joint: {exc}") from None
