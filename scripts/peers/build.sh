#!/usr/bin/env bash
# Builds the two peers of docs/BENCHMARKS.md into DEST:
#   DEST/openvdb_surface  our harness around OpenVDB 10's mesh-to-volume (openvdb_surface.cpp
#                         beside this script; Debian's libopenvdb-dev);
#   DEST/obj2voxel        obj2voxel (MIT; github.com/Eisenwave/obj2voxel at commit 9fb8ae2 with  check-words: allow (the peer's pinned source)
#                         its submodules), from a source tarball that is not part of this
#                         repository: OBJ2VOXEL_SRC, default
#                         ../shared/peers/src/obj2voxel-9fb8ae2.tar.gz (its top folder: obj2voxel/).
# Installs cmake, g++ and libopenvdb-dev with apt if missing (root). About 5 minutes on 2 cores.
#
#   scripts/peers/build.sh DEST
set -euo pipefail
[[ $# -eq 1 ]] || { sed -n 2,11p "$0"; exit 2; }
here=$(cd "$(dirname "$0")" && pwd)
dest=$(mkdir -p "$1" && cd "$1" && pwd)
src="${OBJ2VOXEL_SRC:-$here/../../../shared/peers/src/obj2voxel-9fb8ae2.tar.gz}"
[[ -f "$src" ]] || { echo "$src: obj2voxel's source tarball not found (set OBJ2VOXEL_SRC)" >&2; exit 1; }
if ! dpkg -s libopenvdb-dev cmake >/dev/null 2>&1; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq --no-install-recommends cmake g++ make libopenvdb-dev libtbb-dev libboost-dev >/dev/null
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
tar -xzf "$src" -C "$work"
# GCC 12 needs a few standard headers that obj2voxel's sources include only transitively elsewhere.
cmake -S "$work/obj2voxel" -B "$work/obj2voxel/build" -DCMAKE_BUILD_TYPE=Release \
  -DCMAKE_CXX_FLAGS="-include cstdint -include limits -include exception -include cstring -include stdexcept" >/dev/null
cmake --build "$work/obj2voxel/build" -j"$(nproc)" >/dev/null
cp "$work/obj2voxel/build/obj2voxel" "$dest/"
g++ -O2 -std=c++17 "$here/openvdb_surface.cpp" -o "$dest/openvdb_surface" -lopenvdb -ltbb -lImath-3_1
echo "built: $dest/obj2voxel $dest/openvdb_surface"
