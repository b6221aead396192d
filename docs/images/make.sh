#!/bin/sh
# Remakes every picture in docs/images/ (the README's) with the rbvh binary, from built-in scenes
# only, so anyone can check them:   sh docs/images/make.sh [path/to/rbvh]
# The binary defaults to the repository's target/release/rbvh (`cargo build --release`). Renders on lavapipe are
# deterministic; the chart's speeds are one small timed run and differ from run to run.
set -eu

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
rbvh=${1:-$root/target/release/rbvh}
case $rbvh in /*) ;; *) rbvh=$(pwd)/$rbvh ;; esac   # a path given relative to where it was run
[ -x "$rbvh" ] || { echo "make.sh: no rbvh binary at $rbvh (build it with cargo build --release, or pass its path)" >&2; exit 1; }

cd "$root"
out=docs/images
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# A close view of the default scene's bumpy sphere, cube and sphere, where the levels differ.
close="--camera-eye=-2.6,1.6,3.2 --camera-target=-0.7,0.45,0.6 --vfov 32 --width 256 --height 192"

# The default scene as `rbvh render` draws it (exact BVH, its own camera).
"$rbvh" render --width 256 --height 192 --out $out/default.png

# Quality levels: the exact BVH and the RBVH at Q0..Q4, same close view.
"$rbvh" render $close --out $out/closeup-exact.png
for q in 0 1 2 3 4; do
    "$rbvh" render $close --method rbvh --quality $q --out $out/closeup-q$q.png
done

# The same close view through an RBVH built from 300,000 points sampled over the scene (Q2).
"$rbvh" render $close --method rbvh --quality 2 --points 300000 --out $out/closeup-points-q2.png

# Heat maps of traversal steps per pixel, exact BVH and RBVH Q2, on one scale (0..40 steps).
"$rbvh" render --width 320 --height 240 --out "$tmp/exact.png" \
    --heatmap $out/heatmap-exact.png --heatmap-max 40
"$rbvh" render --width 320 --height 240 --method rbvh --quality 2 --out "$tmp/q2.png" \
    --heatmap $out/heatmap-q2.png --heatmap-max 40

# The bench's speed-vs-error chart, from a small run (primary rays, 256x256, 3 timed runs).
"$rbvh" bench --scene default --quality all --rays primary --width 256 --height 256 --runs 3 \
    --plot "$tmp/bench"
cp "$tmp/bench/default/speed_vs_error.svg" $out/speed_vs_error.svg

# Painting: strokes aimed through the default camera at 256x192, painted into an RBVH Q2's colour
# channel; the saved RBVH is then rendered from the close view, where the paint stays on the surfaces.
"$rbvh" paint --strokes $out/strokes.txt --out "$tmp/painted.rbvh" --width 256 --height 192 \
    --after $out/paint-after.png
"$rbvh" render $close --rbvh "$tmp/painted.rbvh" --out $out/paint-closeup.png

ls -l $out
