#!/usr/bin/env bash
# Builds loopgate's Debian package and proves the installed copy works on its own: the package is unpacked
# into a temporary root (dpkg -x, no root rights needed), and the demo runs from an unrelated folder with the
# unpacked binary, its presets, its configs and its plot script - nothing of the source or build tree.
#   scripts/package_test.sh [--keep DIR] [BUILD_DIR]   (default build/release; configured if needed)
# --keep DIR copies the tested .deb into DIR (packaging/loopgate.def builds its image from out/package/).
# Also checks that `cmake --install` into a prefix gives the same layout. Exit 0 when every check passed.
set -euo pipefail
cd "$(dirname "$0")/.."
keep=""
if [[ ${1:-} == --keep ]]; then
  keep=$2
  shift 2
fi
build=${1:-build/release}
[ -f "$build/CMakeCache.txt" ] || cmake --preset release >/dev/null
cmake --build "$build" --target loopgate
tmp=$(mktemp -d "${TMPDIR:-/tmp}/loopgate-package-test.XXXXXX")
trap 'rm -rf "$tmp"' EXIT
fail() { echo "package_test: FAIL: $*" >&2; exit 1; }

# The package: built, its metadata, its files.
(cd "$build" && cpack -G DEB -B "$tmp/deb" >/dev/null)
deb=$(ls "$tmp"/deb/loopgate_*.deb 2>/dev/null | head -1)
[ -n "$deb" ] || fail "cpack wrote no loopgate_*.deb into $tmp/deb"
echo "package_test: built $(basename "$deb") ($(du -k "$deb" | cut -f1) kB)" >&2
depends=$(dpkg-deb -f "$deb" Depends)
echo "package_test: Depends: $depends" >&2
for needed in libc6 libopencv python3-matplotlib; do
  [[ $depends == *"$needed"* ]] || fail "Depends lacks $needed: $depends"
done
dpkg-deb -x "$deb" "$tmp/root"
root=$tmp/root/usr
for f in bin/loopgate share/loopgate/configs/demo.yaml share/loopgate/configs/sim/demo.yaml \
         share/loopgate/scripts/plot.py share/doc/loopgate/README.md; do
  [ -e "$root/$f" ] || fail "the package lacks /usr/$f"
done

# cmake --install: the same layout under a prefix.
cmake --install "$build" --prefix "$tmp/prefix" >/dev/null
for f in bin/loopgate share/loopgate/configs/sim/demo.yaml share/loopgate/scripts/plot.py; do
  [ -e "$tmp/prefix/$f" ] || fail "cmake --install did not write $tmp/prefix/$f"
done

# The demo from the unpacked package, run from an empty folder. The presets and plot.py must be the package's,
# not the source tree's compiled into the binary: `simulate --help` names the preset folder in use, and
# LOOPGATE_PLOT_SCRIPT is unset so compare finds plot.py itself.
unset LOOPGATE_PLOT_SCRIPT
mkdir "$tmp/work"
cd "$tmp/work"
help=$("$root/bin/loopgate" simulate --help)
[[ $help == *"$root/share/loopgate/configs/sim"* ]] || fail "simulate --help does not name the package's presets: $help"
"$root/bin/loopgate" simulate --preset demo --out demo >/dev/null 2>"$tmp/simulate.log" ||
  { cat "$tmp/simulate.log" >&2; fail "simulate --preset demo"; }
"$root/bin/loopgate" compare --config "$root/share/loopgate/configs/demo.yaml" --dataset demo \
  --out demo-compare --set output.progress=off >"$tmp/compare.out" 2>"$tmp/compare.log" ||
  { cat "$tmp/compare.out" "$tmp/compare.log" >&2; fail "compare on the demo"; }
grep -q "^result:" "$tmp/compare.out" || fail "compare printed no result block"
for png in pr.png plane.png trajectory.png; do
  [ -s "demo-compare/plots/$png" ] || fail "no demo-compare/plots/$png (plot.py from the package)"
done
sed -n '/^result:/,$p' "$tmp/compare.out" >&2
if [[ -n $keep ]]; then
  cd - >/dev/null
  mkdir -p "$keep"
  cp "$deb" "$keep/"
fi
echo "package_test: OK: $(basename "$deb") unpacked; its loopgate ran the demo from an empty folder" >&2
