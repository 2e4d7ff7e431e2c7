"""Every command stays parse -> one library call -> print: no function in rotstar_mrcal/cli/ over 40 lines"""

from __future__ import annotations

import ast
import glob
import os

CLI = os.path.join(os.path.dirname(__file__), "..", "..", "rotstar_mrcal", "cli")
LONGEST = 40


def test_no_long_function_in_the_commands():
    long = []
    for path in sorted(glob.glob(os.path.join(CLI, "*.py"))):
        with open(path) as fh:
            tree = ast.parse(fh.read())
        long += [(os.path.basename(path), n.name, n.end_lineno - n.lineno + 1) for n in ast.walk(tree)
                 if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > LONGEST]
    assert not long, f"functions over {LONGEST} lines (move the work into the library): {long}"
