"""The ``splatray`` command line: ``splatray ARGS...`` (the wheel's console
script) and ``python -m splatray ARGS...`` run the command line of the
``splatray`` binary, compiled into the native module
(:func:`splatray._splatray.main`): the same commands, output (results on
stdout, progress and the one-line error on stderr) and exit status."""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence

from ._splatray import main as _run


def main(argv: Sequence[str] | None = None) -> int:
    """Runs ``splatray`` with ``argv`` (default ``sys.argv[1:]``) and
    returns its exit status. Ctrl-C ends the process as it ends the binary
    (SIGINT's default action; ``splatray view`` still shuts down on it
    itself), not at Python's next bytecode after the work: this is a
    command's entry, not a function for programs to call."""
    args = sys.argv[1:] if argv is None else list(argv)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    sys.stdout.flush()
    sys.stderr.flush()
    return _run(["splatray", *args])


if __name__ == "__main__":
    sys.exit(main())
