#!/usr/bin/env bash
# The README's GPU measurements in a short window of device time: runs them in order of value,
# each within what is left of the budget, writes a results file as each finishes, and stops
# cleanly (nothing half-written) when the budget ends.
#
#   scripts/gpu-window.sh BUDGET_SECONDS OUT_DIR [DATASETS_DIR]
#
# BUDGET_SECONDS  wall time for everything, start-up of each step included
# OUT_DIR         where the results files (JSON, as `rbvh bench --json` and `rbvh shaders --json`
#                 write them) and log.txt go; copy them to docs/results/ and run `rbvh tables`
# DATASETS_DIR    the shared datasets (dragon/dragon_vrip.obj, sponza-dabrovic/sponza.obj), by
#                 default ../shared/datasets beside the repository; steps whose files are missing
#                 are skipped, saying so
#
# Environment: RBVH (the binary; default target/release/rbvh), DEVICE (a part of the device's name;
# default NVIDIA), RBVH_COMMIT (the commit measured, for a tree without .git; inside a repository
# the bench reads it, and whether the code was committed, from git),
# WIDTH/HEIGHT (default 1920x1080), RUNS (default 5).
#
# Order of value: the shaders' registers (seconds), then the dragon close-up and the default scene
# (exact and Q0-Q4) for primary, AO and shadow rays, then the thousand dragons in two levels
# (builds of seconds), then the paper-scale scene (the three ray types in one run) and its
# instanced twin (Q2 flat and in two levels, primary and shadow rays), whose flat builds take
# minutes.
set -uo pipefail

budget=${1:?usage: scripts/gpu-window.sh BUDGET_SECONDS OUT_DIR [DATASETS_DIR]}
out=${2:?usage: scripts/gpu-window.sh BUDGET_SECONDS OUT_DIR [DATASETS_DIR]}
root=$(cd "$(dirname "$0")/.." && pwd)
datasets=$(cd "${3:-$root/../shared/datasets}" 2>/dev/null && pwd || echo "${3:-$root/../shared/datasets}")
rbvh=${RBVH:-$root/target/release/rbvh}
device=${DEVICE:-NVIDIA}
width=${WIDTH:-1920}
height=${HEIGHT:-1080}
runs=${RUNS:-5}
case $budget in ''|*[!0-9]*) echo "BUDGET_SECONDS must be a whole number of seconds, not $budget" >&2; exit 2;; esac
[ -x "$rbvh" ] || { echo "no rbvh binary at $rbvh: build it (cargo build --release) or set RBVH" >&2; exit 2; }
mkdir -p "$out" || exit 2
out=$(cd "$out" && pwd)
# Every path is absolute from here on: the commands run in the repository, whose git the bench
# reads for the commit and whether the code was committed (run elsewhere, it read another
# folder's or none).
case $rbvh in /*) ;; *) rbvh=$(cd "$(dirname "$rbvh")" && pwd)/$(basename "$rbvh");; esac
cd "$root" || exit 2
# Inside the repository the bench reads the commit (and whether the code was committed) from git;
# a tree without .git (as a GPU machine is handed) should be given RBVH_COMMIT.
if [ -z "${RBVH_COMMIT:-}" ] && ! git -C "$root" rev-parse HEAD >/dev/null 2>&1; then
  echo "warning: no git repository at $root and no RBVH_COMMIT: the results will name no commit" >&2
fi
commit=${RBVH_COMMIT:-$(git -C "$root" rev-parse HEAD 2>/dev/null || echo unknown)}
log=$out/log.txt
start=$(date +%s)
left() { echo $(( budget - ($(date +%s) - start) )); }
say() { echo "[$(( $(date +%s) - start ))s] $*" | tee -a "$log" >&2; }

# The scene files name the datasets relative to scenes/; copies under OUT_DIR name DATASETS_DIR.
scene_copy() {
  local from=$root/scenes/$1 to=$out/scenes/$1
  mkdir -p "$out/scenes"
  local escaped; escaped=$(printf '%s' "$datasets" | sed 's/[\\|&]/\\&/g')
  sed "s|\.\./\.\./shared/datasets|$escaped|g" "$from" > "$to" && echo "$to"
}

# step NAME MIN_SECONDS NEEDED_FILE -- COMMAND...: runs COMMAND when at least MIN_SECONDS are left
# and NEEDED_FILE exists, killed when the budget ends (its results file is written atomically, so
# none is left half-written).
step() {
  local name=$1 min=$2 needed=$3; shift 4
  local remaining; remaining=$(left)
  if [ "$remaining" -lt "$min" ]; then
    say "$name: skipped, $remaining s left of the budget (needs about $min)"; return
  fi
  if [ -n "$needed" ] && [ ! -e "$needed" ]; then
    say "$name: skipped, $needed is missing"; return
  fi
  say "$name: started, $remaining s left"
  timeout --signal=TERM --kill-after=5 "$remaining" "$@" >>"$log" 2>&1
  local rc=$?
  case $rc in
    0) say "$name: done" ;;
    124|137) say "$name: stopped, the budget ended"; exit 0 ;;
    *) say "$name: failed (exit $rc, see $log)" ;;
  esac
}

say "rbvh gpu-window: budget ${budget}s, device $device, ${width}x${height}, $runs runs, commit $commit"
base=(--device "$device" --width "$width" --height "$height" --runs "$runs" --allow-invalid)
common=("${base[@]}" --quality all)
dragon=$datasets/dragon/dragon_vrip.obj
closeup=$(scene_copy dragon-closeup.toml)
paper=$(scene_copy paper-scale.toml)
dragons=$(scene_copy dragons-1000.toml)
paper_instanced=$(scene_copy paper-scale-instanced.toml)

step shaders 20 "" -- "$rbvh" shaders --device "$device" --json "$out/shaders-gpu.json"
# A file per ray type for the small scenes, so that the budget's end loses one ray type, not all
# (their builds take seconds); one run of all three for the paper-scale scene, whose builds take
# minutes.
for rays in primary ao shadow; do
  step "dragon-closeup $rays" 60 "$dragon" -- "$rbvh" bench --scene "$closeup" --rays "$rays" "${common[@]}" --json "$out/bench-gpu-dragon-closeup-$rays.json"
  step "default $rays" 40 "" -- "$rbvh" bench --scene default --rays "$rays" "${common[@]}" --json "$out/bench-gpu-default-$rays.json"
done
step "dragons-1000" 90 "$dragon" -- "$rbvh" bench --scene "$dragons" --rays primary,shadow --seam-rays 0 "${common[@]}" --json "$out/bench-gpu-dragons-1000.json"
step "paper-scale" 300 "$datasets/sponza-dabrovic/sponza.obj" -- "$rbvh" bench --scene "$paper" --rays primary,ao,shadow "${common[@]}" --json "$out/bench-gpu-paper-scale.json"
step "paper-scale-instanced" 300 "$datasets/sponza-dabrovic/sponza.obj" -- "$rbvh" bench --scene "$paper_instanced" --rays primary,shadow "${base[@]}" --quality 2 --json "$out/bench-gpu-paper-scale-instanced.json"
say "all steps ended; $(left) s of the budget left"
