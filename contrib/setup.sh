#!/usr/bin/env bash
# SPDX-License-Identifier: LGPL-2.1-or-later
# Shared set-up of contrib/run, contrib/test and contrib/bench (sourced, not run):
# installs the Debian packages shard needs when any is missing, then configures and builds
# a Release build in $SHARD_BUILD (default: build/). Idempotent.
set -euo pipefail

SHARD_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SHARD_BUILD="${SHARD_BUILD:-$SHARD_ROOT/build}"
SHARD_PACKAGES=(cmake make g++ git ccache python3 python3-matplotlib python3-numpy python3-h5py
                openmpi-bin libdeal.ii-dev libeigen3-dev libhdf5-mpi-dev libgtest-dev libsuitesparse-dev
                libopenblas0-serial)

shard_install_packages() {
  local missing=()
  for p in "${SHARD_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  echo "contrib: installing missing Debian packages: ${missing[*]}" >&2
  local sudo=""
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "contrib: need root or sudo to install ${missing[*]}" >&2; exit 1; }
    sudo="sudo"
  fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

shard_build() {
  local jobs
  jobs="$(nproc 2>/dev/null || echo 2)"
  if [ ! -f "$SHARD_BUILD/CMakeCache.txt" ]; then
    cmake -S "$SHARD_ROOT" -B "$SHARD_BUILD" -DCMAKE_BUILD_TYPE=Release >/dev/null
  fi
  cmake --build "$SHARD_BUILD" -j "$jobs" "$@"
}

# ccache (CMakeLists.txt uses it when present) hashes paths below the checkout relative to it, so a
# fresh clone elsewhere (CI, contrib/test from a clean clone) reuses the objects of an earlier build.
export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$SHARD_ROOT}" CCACHE_NOHASHDIR="${CCACHE_NOHASHDIR:-true}"
# Open MPI refuses to run as root unless told; CI and containers run as root.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# One thread per MPI rank (deal.II/TBB): results do not depend on the thread count.
export DEAL_II_NUM_THREADS="${DEAL_II_NUM_THREADS:-1}"
