#!/usr/bin/env python3
"""Write rotstar_mrcal/detect/coma_tables.py: psfbias.computed_coma_table at every reach edgespread uses

SYNOPSIS

    PYTHONPATH=. .venv/bin/python scripts/coma_tables.py      # ~5 s

The default Optics, reaches MIN_REACH to MAX_REACH in BIN_PX steps; the
values with 12 significant digits (the table is a monotone interpolation
grid: the digits beyond do not move a coma by 1e-9 waves).
"""

from __future__ import annotations

import os
import sys

import numpy as np

from rotstar_mrcal.detect import psfbias
from rotstar_mrcal.detect.edgespread import BIN_PX, MAX_REACH, MIN_REACH
from rotstar_mrcal.optics.psf import Optics

OUT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "rotstar_mrcal", "detect",
                   "coma_tables.py")


def main() -> int:
    with open(OUT) as f:
        head = f.read().split("TABLES")[0]
    lines = [head.rstrip("\n"), "", "TABLES: dict[float, tuple[float, ...]] = {"]
    for reach in np.arange(MIN_REACH, MAX_REACH + 1e-9, BIN_PX):
        t = psfbias.computed_coma_table(round(float(reach), 6), Optics())
        lines.append(f"    {round(float(reach), 6)!r}: (" + ", ".join(f"{v:.12g}" for v in t) + "),")
    lines.append("}")
    with open(OUT, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {os.path.relpath(OUT)}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
