#!/usr/bin/env bash
# Re-make the tables of results/full: the three full studies and validate, cold, in one folder.
#
#   bash scripts/full-runs.sh DIR [STEP ...]
#
# STEPs (default all, in this order): range-limit webcam-vs-dslr brightness-diffuser validate.
# Each step writes DIR/<step>/ and resumes from it when run again; a step whose "end <step> rc=0"
# line is in DIR/chain.log is skipped. Renders are cached in DIR/cache (empty at the start: cold).
# Wall times go to DIR/chain.log. Copy the summaries into results/full/ when a step has ended.
# Run it in the background on a machine that keeps DIR:
#   setsid nohup bash scripts/full-runs.sh /work/full >/dev/null 2>&1 &
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: bash scripts/full-runs.sh DIR [STEP ...]}
shift
steps=("$@")
[ ${#steps[@]} -gt 0 ] || steps=(range-limit webcam-vs-dslr brightness-diffuser validate)
mkdir -p "$out"
out=$(cd "$out" && pwd)
export BEACON_SIM_CACHE="$out/cache"
log="$out/chain.log"
bash scripts/setup.sh >/dev/null

run_step() {
    local name=$1
    grep -q "^end $name rc=0" "$log" 2>/dev/null && return 0
    local cmd
    case $name in
        # the sequential designs start from a 2-seed coarse grid within the old full grids' frame counts
        range-limit) cmd=(study range-limit --seeds 2 --target-relative 0.2 --budget-frames 5376) ;;
        webcam-vs-dslr) cmd=(study webcam-vs-dslr --seeds 2 --target-relative 0.2 --budget-frames 7680) ;;
        brightness-diffuser) cmd=(study brightness-diffuser) ;;
        # 2 points of the calibration's set, as the reference run of 2026-11-30 (848 frames); its
        # default of 20 points is ~20 h of T6 frames on the 2-core machine
        validate) cmd=(validate --points 2) ;;
        *) echo "full-runs: unknown step $name (range-limit, webcam-vs-dslr, brightness-diffuser, validate)" >&2
           return 2 ;;
    esac
    echo "start $name $(date -u +%FT%TZ) $(git rev-parse --short HEAD)" >>"$log"
    local t0=$SECONDS rc=0
    .venv/bin/beacon-sim "${cmd[@]}" --out "$out/$name" >"$out/$name.log" 2>&1 || rc=$?
    echo "end $name rc=$rc $(date -u +%FT%TZ) $((SECONDS - t0)) s" >>"$log"
    return $rc
}

for step in "${steps[@]}"; do
    run_step "$step"
done
