#!/usr/bin/env bash
# `make test-fresh`: what CI does, here. Clones the committed HEAD into a temporary folder and runs
# .ci/run there (set-up from nothing, then the README's `make test`), so a file that was never
# committed or a set-up step that only worked in this checkout shows before it lands.
#   HMOCAP_FRESH_KEEP=1   keep the clone (its path is printed)
#   HMOCAP_FRESH_LOAD=1   run a CPU hog on one core meanwhile (the suite must pass on a loaded machine)
#   HMOCAP_FRESH_OTHER_CPU=1  emulate an older x86 CPU (numpy without AVX-512 kernels, OpenBLAS
#                         Haswell kernels, numba compiled for haswell): tolerances must state the
#                         method's precision, not this CPU's rounding
set -euo pipefail
cd "$(dirname "$0")/.."
dir=$(mktemp -d "${TMPDIR:-/tmp}/hmocap_fresh.XXXXXX")
git clone -q . "$dir"
echo "test-fresh: $(git rev-parse --short HEAD) cloned into $dir"
hog=
cleanup() {
  [ -n "$hog" ] && kill "$hog" 2>/dev/null || true
  if [ "${HMOCAP_FRESH_KEEP:-0}" = 1 ]; then echo "test-fresh: kept $dir"; else rm -rf "$dir"; fi
}
trap cleanup EXIT
if [ "${HMOCAP_FRESH_LOAD:-0}" = 1 ]; then
  python3 -c 'while True: pass' & hog=$!
  echo "test-fresh: CPU hog on one core (pid $hog)"
fi
if [ "${HMOCAP_FRESH_OTHER_CPU:-0}" = 1 ]; then
  export NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR" OPENBLAS_CORETYPE=Haswell NUMBA_CPU_NAME=haswell
  echo "test-fresh: emulating an AVX2 (haswell) CPU"
fi
# the clone gets its own venv, its own domain and no variable of this shell's make
unset VIRTUAL_ENV ROS_DOMAIN_ID MAKEFLAGS MAKELEVEL
start=$(date +%s)
status=0
(cd "$dir" && .ci/run) || status=$?
echo "test-fresh: .ci/run exited $status after $(( $(date +%s) - start )) s"
exit $status
