#!/usr/bin/env bash
# Idempotent set-up of pdemfem's run-time stack.
#  1. On Debian as root: the MPI/PETSc/h5py-mpi stack from apt (only what is missing).
#  2. .venv in the repository root, made with the system Python so it sees Debian's
#     petsc4py, mpi4py and MPI-enabled h5py (pip must never resolve those three: pip
#     would put a serial h5py over the MPI one).
#  3. The project in editable mode with its pip dependencies.
# A stamp file keyed on pyproject.toml makes a second run finish in about a second.
set -euo pipefail
cd "$(dirname "$0")/.."
root_dir=$(pwd)

debian_packages=(
  python3-petsc4py python3-mpi4py python3-h5py-mpi python3-venv python3-yaml
  openmpi-bin libopenmpi-dev
  # The gmsh wheel needs these to import on a minimal Debian.
  libglu1-mesa libgl1 libxcursor1 libxft2 libxinerama1
)

missing=()
if command -v dpkg-query >/dev/null 2>&1; then
  for package in "${debian_packages[@]}"; do
    status=$(dpkg-query -W -f='${Status}' "$package" 2>/dev/null || true)
    [[ "$status" == "install ok installed" ]] || missing+=("$package")
  done
fi

if ((${#missing[@]})); then
  if [[ $(id -u) -eq 0 ]] && command -v apt-get >/dev/null 2>&1; then
    echo "install: apt-get install ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "install: missing Debian packages: ${missing[*]}" >&2
    echo "install: run as root, or see README 'Installing on a cluster' for the pip route" >&2
    exit 1
  fi
fi

python=/usr/bin/python3
if [[ ! -x .venv/bin/python ]]; then
  echo "install: creating .venv (system site packages visible)"
  "$python" -m venv --system-site-packages .venv
fi

stamp=.venv/.pdemfem-installed
wanted=$(sha256sum pyproject.toml scripts/install.sh | sha256sum | cut -c1-16)
if [[ -f "$stamp" && "$(cat "$stamp")" == "$wanted" ]]; then
  exit 0
fi

# Pin numpy to the version Debian's petsc4py/h5py were built against.
numpy_version=$(.venv/bin/python -c 'import numpy; print(numpy.__version__)')
constraints=$(mktemp)
trap 'rm -f "$constraints"' EXIT
printf 'numpy==%s\n' "$numpy_version" > "$constraints"
echo "install: pip install -e .[test] (numpy pinned to $numpy_version)"
.venv/bin/python -m pip install -q --disable-pip-version-check -c "$constraints" -e "$root_dir[test]"
echo "$wanted" > "$stamp"
echo "install: done"
