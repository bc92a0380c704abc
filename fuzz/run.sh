#!/usr/bin/env bash
# Fuzzes every parser a user's file reaches (issue 17) with cargo-fuzz on the nightly
# toolchain, each target for RUNS executions (default 10⁷), seeded from tests/fixtures.
# Prints one line per target: executions, seconds, crashes (inputs kept under
# fuzz/artifacts/TARGET; turn each into a case of tests/fuzz_regressions.rs).
#
#     cargo install cargo-fuzz
#     bash fuzz/run.sh [RUNS] [TARGET...]
#     FUZZ_MAX_SECONDS=600 bash fuzz/run.sh 10000000 nifti   # at most 10 minutes
#     FUZZ_MAX_LEN=4096 bash fuzz/run.sh 8000000 nifti       # inputs up to 4 KiB (default 64 KiB)
#
# A benchmark-style script: not run by CI (10⁷ executions of nine targets take hours on 2 cores).
set -euo pipefail
cd "$(dirname "$0")"
runs=${1:-10000000}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(scene_json mesh_obj mesh_stl mesh_ply calibration label_png session nifti trajectory)
fi
fx=../tests/fixtures
seeds=seeds
rm -rf "$seeds"
mkdir -p "$seeds" logs
for t in "${targets[@]}"; do mkdir -p "$seeds/$t" "corpus/$t"; done
prefixed() { # BYTE FILE OUT: the file behind one selector byte
  { printf "\\x$(printf %02x "$1")"; cat "$2"; } > "$3"
}
# Inputs that once crashed or hung a target stay in its seeds (tests/fuzz_regressions.rs).
for t in "${targets[@]}"; do
  for f in "$fx"/fuzz_regressions/"$t"-*; do [ -f "$f" ] && cp "$f" "$seeds/$t/"; done
done
cp "$fx/handmade_scene/scene.json" "$seeds/scene_json/" 2>/dev/null || true
cp "$fx/handmade_scene/meshes/kidney.obj" "$seeds/mesh_obj/" 2>/dev/null || true
cp "$fx/handmade_scene/meshes/tumour.stl" "$seeds/mesh_stl/" 2>/dev/null || true
cp "$fx/handmade_scene/meshes/hidden.ply" "$seeds/mesh_ply/" 2>/dev/null || true
if [ -d "$seeds/calibration" ]; then
  for f in "$fx"/calib/*.yml; do prefixed 0 "$f" "$seeds/calibration/$(basename "$f")"; done
  for f in "$fx"/calib/*.xml; do prefixed 2 "$f" "$seeds/calibration/$(basename "$f")"; done
  for f in "$fx"/calib/*.txt; do prefixed 3 "$f" "$seeds/calibration/$(basename "$f")"; done
fi
if [ -d "$seeds/label_png" ]; then
  i=0
  for f in $(find "$fx/handmade_scene" -name '*.png' | sort); do
    cp "$f" "$seeds/label_png/$i.png"; i=$((i + 1))
  done
fi
if [ -d "$seeds/session" ]; then
  printf '%s' '{"format":"endofuse-session/1","scene":"demo","seeds":[{"camera":0,"frame":0,"width":64,"height":48,"runs":[[3000,0],[72,1]]}],"results":[]}' \
    > "$seeds/session/minimal.json"
fi
if [ -d "$seeds/nifti" ]; then
  python3 - "$seeds/nifti/tiny.nii" <<'PY'
import struct, sys
h = bytearray(348)
struct.pack_into("<i", h, 0, 348)
struct.pack_into("<8h", h, 40, 3, 4, 4, 3, 1, 1, 1, 1)  # dim
struct.pack_into("<hh", h, 70, 2, 8)                     # uint8, 8 bits per voxel
struct.pack_into("<8f", h, 76, 1, 0.8, 0.8, 2.5, 1, 1, 1, 1)  # pixdim
struct.pack_into("<f", h, 108, 352.0)                    # vox_offset
h[123] = 2                                               # mm
struct.pack_into("<hh", h, 252, 1, 0)                    # qform_code 1
h[344:348] = b"n+1\0"
data = bytes([0] * 20 + [1] * 16 + [2] * 4 + [0] * 8)
open(sys.argv[1], "wb").write(bytes(h) + b"\0" * 4 + data)
PY
  prefixed 0 "$seeds/nifti/tiny.nii" "$seeds/nifti/tiny.sel"
  rm "$seeds/nifti/tiny.nii"
  prefixed 1 "$fx/ct/kits19_case_00010_cropped.nii.gz" "$seeds/nifti/kits_cropped.sel"
fi
if [ -d "$seeds/trajectory" ]; then
  printf '%s' '{"frames":[{"frame":0,"affine":[1,0,0,0,0,1,0,0,0,0,1,150],"shape":{"kidney":[0.5,-0.2]},"centroids":{"kidney":[0,0,150],"tumour":[5,2,148]},"cameras":[]},{"frame":3,"affine":[1,0,0,1,0,1,0,0,0,0,1,151],"energy":2.5,"iterations":7}]}' \
    > "$seeds/trajectory/minimal.json"
fi

printf '| target | executions | seconds | crashes |\n|---|---|---|---|\n'
for t in "${targets[@]}"; do
  start=$(date +%s)
  # -rss_limit_mb: an input that makes a parser allocate more than 2 GiB is a finding.
  cargo +nightly fuzz run --release "$t" "corpus/$t" "$seeds/$t" -- \
    -runs="$runs" -max_total_time="${FUZZ_MAX_SECONDS:-0}" -max_len="${FUZZ_MAX_LEN:-65536}" -rss_limit_mb=2048 -timeout=10 -print_final_stats=1 \
    > "logs/$t.log" 2>&1 || true
  secs=$(( $(date +%s) - start ))
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "logs/$t.log" | grep -o '[0-9]*$' | tail -1)
  crashes=$(find "artifacts/$t" -type f 2>/dev/null | wc -l)
  printf '| %s | %s | %s | %s |\n' "$t" "${execs:-?}" "$secs" "$crashes"
done
