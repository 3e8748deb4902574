"""The ``subid`` command line.

::

    subid identify DATA --inputs u1,u2 --outputs y1 --dt 0.1 --method ls --out DIR
    subid track DATA --inputs u --outputs y --method recursive --order 4 --out DIR
    subid simulate MODEL --input FILE --out FILE
    subid compare MODEL... --data FILE
    subid convert MODEL --to dt=0.01|ct|mat|json|control|scipy
    subid demo --out demo_out
    subid gallery --out docs/gallery.md
    subid methods

``DATA`` is a file (CSV/TSV/TXT/DAT, ``.npz`` or ``.mat``, see
:func:`subid.read`) or ``dataset:NAME`` for a bundled DaISy record
(``subid methods`` lists both). User errors (bad column names, missing or
empty files, non-numeric cells, unusable data) print one line naming the
file and the problem and exit with status 2; ``--debug`` adds the traceback.
Progress bars appear only on a terminal and never with ``--quiet``.

Identification methods are looked up in :data:`subid.registry.METHODS`
(:data:`METHODS` here: those the command line offers), which imports each
method's module only when it is used, so a method whose module is absent
from this version is reported as "not available" instead of breaking the
tool. The options ``--option KEY=VALUE`` accepts are the registry's
``MethodSpec.options``.
"""

from __future__ import annotations

import logging
import sys
import traceback
import warnings

import click

import subid.cli._shared as _shared
from subid import _blas
from subid.cli._interrupt import interrupts

# Each command registers itself on the group when its module is imported (one module per
# command, issue 24). The names the command line had here stay importable from here.
from subid.cli._shared import (  # noqa: F401
    EXIT_USER_ERROR,
    IDENTIFY,
    METHODS,
    MethodSpec,
    _HintFilter,
    _one_line,
    _show_warning,
    _State,
    _usage_line,
    available_methods,
    cli,
    cli_hint,
    load_data,
    load_model,
    load_online,
    log,
    new_online,
    run_batch,
)
from subid.cli.compare import compare  # noqa: F401
from subid.cli.convert import convert  # noqa: F401
from subid.cli.demo_commands import demo, gallery  # noqa: F401
from subid.cli.identify import identify  # noqa: F401
from subid.cli.methods import methods_command  # noqa: F401
from subid.cli.simulate import simulate  # noqa: F401
from subid.cli.track import track  # noqa: F401
from subid.errors import SubidError
from subid.methods.registry import MethodUnavailableError  # noqa: F401

__all__ = ["main", "METHODS", "MethodSpec", "MethodUnavailableError", "available_methods"]


# ---------------------------------------------------------------------------
# entry point
# ---------------------------------------------------------------------------
def main(argv=None) -> int:
    """Run the command line; returns the exit status (0 ok, 2 user error).

    Parameters
    ----------
    argv : list of str, optional
        Arguments without the program name (default ``sys.argv[1:]``).
    """
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("subid: %(levelname)s: %(message)s"))
    logger = logging.getLogger("subid")
    previous = (_shared._HANDLER, logger.level, logger.propagate)
    _shared._HANDLER = handler       # the level --quiet/--verbose/--debug set
    handler.setLevel(logging.WARNING)
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING)
    logger.propagate = False
    state = _State()
    state.argv = args
    handler.addFilter(_HintFilter(state))      # library hints in the command's options
    with interrupts() as sigint:
        try:
            status = _run(args, state, debug, sigint)
        finally:
            logger.removeHandler(handler)
            _shared._HANDLER, level, propagate = previous
            logger.setLevel(level)
            logger.propagate = propagate
        if status != 130 and sigint.pending:
            # an interrupt Python dropped (in a finaliser) and the command ended first
            click.echo("subid: interrupted", err=True)
            status = 130
        return status


def _run(args, state, debug, sigint) -> int:
    """Run one command; returns its exit status, errors turned into one line."""
    try:
        try:
            # restores showwarning afterwards; one BLAS thread unless the user chose
            # (subid._blas: many times faster on a machine whose cores are shared)
            with warnings.catch_warnings(), _blas.serial():
                warnings.showwarning = _show_warning
                rv = cli.main(args=args, prog_name="subid", standalone_mode=False, obj=state)
        except click.exceptions.Exit as exc:
            return exc.exit_code
        except click.UsageError as exc:
            click.echo(f"subid: error: {_usage_line(exc)}", err=True)
            return EXIT_USER_ERROR
        except click.ClickException as exc:
            exc.show()
            return EXIT_USER_ERROR
        except click.exceptions.Abort:
            sigint.handled()
            click.echo("Aborted!", err=True)
            return 130
        return rv if isinstance(rv, int) else 0
    except KeyboardInterrupt:
        sigint.handled()
        click.echo("subid: interrupted", err=True)
        return 130
    except MemoryError:
        click.echo("subid: error: out of memory: the record (or a step of the method on it) "
                   "does not fit in this machine's memory; for a large file use "
                   "'subid identify FILE --stream' (bounded memory), or identify a part of "
                   "the record", err=True)
        return EXIT_USER_ERROR
    except (SubidError, OSError, ImportError) as exc:
        if debug:
            traceback.print_exc()
        click.echo(f"subid: error: {cli_hint(_one_line(exc), state)}", err=True)
        return EXIT_USER_ERROR
