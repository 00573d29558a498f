#!/usr/bin/env bash
# Regenerates src/bindings.rs from the installed libfreenect.h with bindgen
# (the configuration is generate.rs; tests/bindings_up_to_date.rs checks the
# committed file against it).
#
# Needs Debian's libfreenect-dev (the header) and libclang-dev (bindgen loads
# libclang at run time):  apt-get install libfreenect-dev libclang-dev
# FREENECT_HEADER=/path/to/libfreenect.h picks another header.
set -euo pipefail
cd "$(dirname "$0")"
out="$PWD/src/bindings.rs"
# The generator is an example of this crate, so the crate must build while it
# runs: it builds with empty bindings, whatever state the old ones are in.
old=$(mktemp)
trap 'rm -f "$old"' EXIT
if [ -f "$out" ]; then cp "$out" "$old"; fi
: > "$out"
if ! cargo run --quiet -p freenect-sys --example regenerate -- "$out"; then
  cp "$old" "$out"
  echo "regenerate.sh: failed; src/bindings.rs left as it was" >&2
  exit 1
fi
