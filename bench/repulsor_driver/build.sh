#!/bin/sh
# Fetch Repulsor at the pinned commits and build the benchmark driver (bench only: Repulsor is
# never a dependency of the add-on, and none of its code is in this repository).
#
#     bench/repulsor_driver/build.sh [DIR]
#
# DIR defaults to $REPULSOR_BUILD, else to build/repulsor in this checkout (git ignores build/;
# `make clean` removes it), which is where bench/repulsor_compare.py looks for the driver
# unless --driver says otherwise. A relative DIR is taken from the current directory.
#
# DIR/Repulsor gets Repulsor 5db79ff with its submodules Tensors 6de1178 and (inside Tensors)
# Tools dfa339a, plus upstream Tools 0525a91's change to src/ParallelAlgorithms.hpp ("Fixed a
# bug in Accumulate"; without it the energy is NaN in most runs); DIR/driver/driver is the
# binary bench/repulsor_compare.py runs (--driver). Needs git, clang 19 and libc++ 19, OpenBLAS
# (pthread) and LAPACKE:
#     apt-get install clang-19 libc++-19-dev libc++abi-19-dev liblapacke-dev libopenblas-pthread-dev
# GIT_BASE overrides where the three repositories are cloned from (default GitHub). Compiling
# takes 2-14 minutes here; run it under nice while anything else is measured.
set -eu
HERE=$(cd "$(dirname "$0")" && pwd)
ROOT=$(cd "$HERE/../.." && pwd)
DIR=${1:-${REPULSOR_BUILD:-$ROOT/build/repulsor}}
BASE=${GIT_BASE:-https://github.com/HenrikSchumacher}
CXX=${CXX:-clang++-19}
mkdir -p "$DIR/driver"
R="$DIR/Repulsor"
clone() {  # repository, commit, destination (an empty submodule directory is cloned into;
           # a clone made before is only checked out again)
    [ -e "$3/.git" ] || git clone -q "$BASE/$1" "$3"
    git -C "$3" checkout -q "$2"
}
clone Repulsor 5db79ff19cd8bbd17dafdd256017aa690d70b392 "$R"
clone Tensors 6de11784d4d54403091410d9b622281c28e5f211 "$R/submodules/Tensors"
T="$R/submodules/Tensors/submodules/Tools"
clone Tools dfa339a6d599fb166d543329a6b718a328a0d384 "$T"
# the fix, once (a build run again finds the file changed already)
if git -C "$T" diff --quiet -- src/ParallelAlgorithms.hpp; then
    git -C "$T" diff 0525a91~1 0525a91 -- src/ParallelAlgorithms.hpp | git -C "$T" apply
fi
OPENBLAS_INC=/usr/include/x86_64-linux-gnu/openblas-pthread
OPENBLAS_LIB=/usr/lib/x86_64-linux-gnu/openblas-pthread
set -x
"$CXX" -std=c++20 -stdlib=libc++ -O3 -march=native -fenable-matrix -pthread -DNDEBUG \
    -Wno-c++11-narrowing -I"$R" -I"$OPENBLAS_INC" \
    "$HERE/driver.cpp" -o "$DIR/driver/driver.new" \
    -L"$OPENBLAS_LIB" -Wl,-rpath,"$OPENBLAS_LIB" -lopenblas -llapacke -lm
mv "$DIR/driver/driver.new" "$DIR/driver/driver"
