"""Numbers in the documentation written by the command that measures them

SYNOPSIS

    >>> import os, tempfile
    >>> from rotstar_lab.docblock import rewrite_block
    >>> fn = os.path.join(tempfile.mkdtemp(), "doc.md")
    >>> _ = open(fn, "w").write("intro\\n<!-- bench:accuracy:begin -->\\nold\\n<!-- bench:accuracy:end -->\\nend\\n")
    >>> rewrite_block(fn, "bench:accuracy", "| a | b |\\n|---|---|")
    True
    >>> print(open(fn).read(), end="")
    intro
    <!-- bench:accuracy:begin -->
    | a | b |
    |---|---|
    <!-- bench:accuracy:end -->
    end
    >>> rewrite_block(fn, "bench:accuracy", "| a | b |\\n|---|---|")   # unchanged
    False

A block is the lines between `<!-- NAME:begin -->` and `<!-- NAME:end -->`,
each marker on a line of its own (Markdown shows neither). `make bench` and
`make demo` rewrite theirs; by hand, edit the text around the blocks only.
"""

from __future__ import annotations

import re


class BlockError(ValueError):
    """The file lacks the block's markers, or has them more than once or out of order"""


def rewrite_block(path: str, name: str, text: str) -> bool:
    """Replace the lines between NAME's markers in path by text; True if the file changed"""
    with open(path) as f:
        old = f.read()
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    b = [m.end() for m in re.finditer(rf"^{re.escape(begin)}[ \t]*\n", old, re.M)]
    e = [m.start() for m in re.finditer(rf"^{re.escape(end)}[ \t]*$", old, re.M)]
    if len(b) != 1 or len(e) != 1 or e[0] < b[0]:
        raise BlockError(f"{path}: needs one '{begin}' line followed by one '{end}' line "
                         f"(found {len(b)} and {len(e)})")
    new = old[:b[0]] + text.rstrip("\n") + "\n" + old[e[0]:]
    if new == old:
        return False
    with open(path, "w") as f:
        f.write(new)
    return True
