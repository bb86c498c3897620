#!/bin/sh
# Renames the lettered subsections of shard parameter files after 'H - Contact' was inserted
# (issue 6): H - Boundary conditions -> I, I - Time integration -> J, J - Output -> K,
# K - Quantities -> L. Edits the given files in place; run it once per file.
# Usage: contrib/utilities/rename_subsections.sh scene.prm [more files...]
set -eu
[ $# -gt 0 ] || { echo "usage: $0 FILE..." >&2; exit 2; }
for f in "$@"; do
  sed -i \
    -e 's/K - Quantities/L - Quantities/g' \
    -e 's/J - Output/K - Output/g' \
    -e 's/I - Time integration/J - Time integration/g' \
    -e 's/H - Boundary conditions/I - Boundary conditions/g' \
    "$f"
done
