#!/usr/bin/env bash
# Packs the staged binaries and libraries for the lent GPU machine (scripts/gpu/prepare.sh
# runs it last): DIR's bin/, lib/, base/ and trace/ into one solid archive,
# DIR/staged.tar.xz, at xz's highest preset. The binaries share most of their code (the
# static libstrata in each), which a solid archive with xz -9's 64 MiB window stores once:
# eight test and benchmark binaries take about 4.5 MB together, where compressed one by
# one they took 15.6. To add binaries to a packed set (e.g. another commit's into base/,
# for an A/B run), put them in DIR/base/ and run this again: it unpacks the archive first.
# scripts/gpu/unpack.sh undoes it on the device.
#   Usage: bash scripts/gpu/pack.sh [DIR]   (default .carry)
set -euo pipefail
dir=${1:-.carry}
if [ -f "$dir/staged.tar.xz" ]; then
  xz -dc "$dir/staged.tar.xz" | tar -C "$dir" -xf -
  rm -f "$dir/staged.tar.xz"
fi
# files compressed one by one (an older staging) are unpacked first, to be packed together
for z in "$dir"/lib/*.xz "$dir"/bin/*.xz "$dir"/base/*.xz "$dir"/trace/*.xz; do
  [ -f "$z" ] && xz -d -f "$z"
done
# the binaries run from the archive as they are (tar keeps the mode)
for d in bin base; do [ -d "$dir/$d" ] && find "$dir/$d" -type f -exec chmod +x {} +; done
parts=()
for d in bin lib base trace; do [ -d "$dir/$d" ] && parts+=("$d"); done
[ ${#parts[@]} -gt 0 ] || { echo "pack.sh: nothing staged in $dir" >&2; exit 1; }
tar -C "$dir" -cf - "${parts[@]}" | xz -9 -T1 >"$dir/staged.tar.xz"
for d in "${parts[@]}"; do rm -rf "${dir:?}/$d"; done
du -sh "$dir"
