#!/bin/sh
# Install rotstar-mrcal with plain pip (no uv) into a new virtualenv:
#   scripts/pip_install.sh [VENV]        (default: venv; PYTHON: the Python >= 3.12 `make python` finds)
# mrcal's wheel declares pyfltk, whose only release here is a source package that
# needs FLTK 1.4 to build ("fltk-config not found"); the wheel already vendors the
# fltk module, so mrcal is installed without its declared dependencies, then those
# dependencies but pyfltk, then this package without dependencies (pip would
# resolve mrcal's again) and then this package's own dependencies.
set -e
V=${1:-venv}
HERE=$(cd "$(dirname "$0")/.." && pwd)
PY=${PYTHON:-$(make -s -C "$HERE" python)}
"$PY" -m venv "$V"
"$V/bin/pip" install -q --upgrade pip
"$V/bin/pip" install -q --no-deps mrcal
"$V/bin/python" -c 'import importlib.metadata as m; print("\n".join(r for r in m.requires("mrcal") if not r.startswith("pyfltk")))' > "$V/mrcal-requirements.txt"
"$V/bin/pip" install -q -r "$V/mrcal-requirements.txt"
"$V/bin/python" -c 'import sys, tomllib; d = tomllib.load(open(sys.argv[1], "rb"))["project"]["dependencies"]; print("\n".join(r for r in d if not r.startswith("mrcal")))' "$HERE/pyproject.toml" > "$V/requirements.txt"
"$V/bin/pip" install -q -r "$V/requirements.txt"
"$V/bin/pip" install -q --no-deps "$HERE"
"$V/bin/python" -c 'import importlib.metadata as m, mrcal, rotstar_mrcal.validate.calibrate; print("mrcal", m.version("mrcal"), "rotstar-mrcal", m.version("rotstar-mrcal"))'
