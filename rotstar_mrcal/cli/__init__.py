"""The commands: each parses its arguments, makes one library call and prints (cli.common.run)

A Ctrl-C while a command still imports its modules (a second or two: numpy, OpenCV, mrcal) ends it as one
during its run does: one line 'rotstar-x: interrupted' and exit 130, not a KeyboardInterrupt traceback.
The handler is set here, the first of our modules a console script imports, and only in a console script
whose SIGINT is Python's own (not in a program that imports the commands, nor where Ctrl-C is ignored, as
in `cmd &`); cli.common.run gives SIGINT back to Python's handler before the command runs.
"""

import os
import signal
import sys


def interrupted_while_starting(signum, frame):
    sys.stderr.write(f"{os.path.basename(sys.argv[0])}: interrupted\n")
    raise SystemExit(130)


if (os.path.basename(sys.argv[0] if sys.argv else "").startswith("rotstar-")
        and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
    signal.signal(signal.SIGINT, interrupted_while_starting)
