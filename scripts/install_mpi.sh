#!/usr/bin/env bash
# The petsc engine's extras (make install-mpi): Debian's PETSc 3.18 (with PT-Scotch, MUMPS,
# hypre, parallel HDF5) and Open MPI from apt, petsc4py 3.18.5 built against that PETSc for the
# given Python, and mpi4py's wheel. Usage: scripts/install_mpi.sh PYTHON
set -euo pipefail
PY="$1"
PETSC_DIR=/usr/lib/petscdir/petsc3.18/x86_64-linux-gnu-real
SUDO=$([ "$(id -u)" = 0 ] && echo "" || echo sudo)
if ! [ -d "$PETSC_DIR" ] || ! command -v mpirun >/dev/null; then
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
    petsc-dev libopenmpi-dev openmpi-bin >/dev/null
fi
if ! "$PY" -c "import petsc4py" 2>/dev/null; then
  # petsc4py 3.18's build predates setuptools 70's linker options and finds numpy's headers
  # only through CFLAGS; it is built in a scratch environment of the same Python
  build=$(mktemp -d)
  "$PY" -m venv "$build/env"
  "$build/env/bin/pip" install --quiet "setuptools<70" wheel \
    "numpy==$("$PY" -c 'import numpy; print(numpy.__version__)')"
  CFLAGS="-I$("$build/env/bin/python" -c 'import numpy; print(numpy.get_include())')" \
    PETSC_DIR="$PETSC_DIR" PETSC_ARCH="" "$build/env/bin/pip" wheel --quiet \
    --no-build-isolation --no-deps -w "$build/wheels" "petsc4py==3.18.5"
  "$PY" -m pip install --quiet "$build"/wheels/petsc4py-*.whl
  rm -rf "$build"
fi
"$PY" -m pip install --quiet "mpi4py>=4,<5"
"$PY" -c "import petsc4py, mpi4py; print('petsc4py', petsc4py.__version__, 'mpi4py', mpi4py.__version__)"
