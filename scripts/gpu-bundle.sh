#!/usr/bin/env bash
# A folder to copy to a machine that has a GPU and its driver but no Rust toolchain, no Vulkan
# loader and no network, so that the GPU tables can be measured there in a short window: the
# stripped binary, scripts/gpu-window.sh and the scene files it runs, the datasets those read
# (xz-compressed), Debian's Vulkan loader package, and run.sh, which unpacks them and runs the
# window.
#
#   scripts/gpu-bundle.sh OUT_DIR [DATASETS_DIR]      (here, after cargo build --release)
#   OUT_DIR/run.sh BUDGET_SECONDS [RESULTS_DIR]        (there; results in OUT_DIR/results)
#
# OUT_DIR       the bundle (made anew; about 21 MB with the datasets): give it a git-ignored
#               place, such as gpu-bundle/ in the repository
# DATASETS_DIR  the shared datasets (dragon/dragon_vrip.obj, sponza-dabrovic/), by default
#               ../shared/datasets beside the repository; what is missing is left out, saying so,
#               and gpu-window.sh skips the steps that need it
#
# Environment: RBVH (the binary; default target/release/rbvh), LOADER_DEB (a libvulkan1 .deb to
# include; by default `apt-get download libvulkan1` fetches Debian's; `none` leaves it out, for a
# machine that has a loader). run.sh takes gpu-window.sh's DEVICE, WIDTH, HEIGHT and RUNS.
set -euo pipefail

out=${1:?usage: scripts/gpu-bundle.sh OUT_DIR [DATASETS_DIR]}
root=$(cd "$(dirname "$0")/.." && pwd)
datasets=${2:-$root/../shared/datasets}
rbvh=${RBVH:-$root/target/release/rbvh}
[ -x "$rbvh" ] || { echo "no rbvh binary at $rbvh: build it (cargo build --release) or set RBVH" >&2; exit 2; }
command -v xz >/dev/null || { echo "xz is missing (Debian: apt install xz-utils): it compresses the datasets" >&2; exit 2; }
commit=${RBVH_COMMIT:-$(git -C "$root" rev-parse HEAD 2>/dev/null || echo unknown)}
if [ "$commit" != unknown ] && [ -n "$(git -C "$root" status --porcelain --untracked-files=no 2>/dev/null)" ]; then
  echo "warning: $root has uncommitted changes: the results will name $commit, which is not the code that ran" >&2
fi

# OUT_DIR is made anew: refused where it holds anything but an earlier bundle, or holds the
# repository, so that a slip of the argument deletes nothing else.
if [ -e "$out" ]; then
  existing=$(cd "$out" && pwd)
  case $root/ in "$existing"/*) echo "$out holds the repository: give the bundle a folder of its own" >&2; exit 2;; esac
  if [ -n "$(ls -A "$out")" ] && { [ ! -f "$out/run.sh" ] || [ ! -f "$out/rbvh" ]; }; then
    echo "$out exists and is not a bundle: give the bundle a new or empty folder" >&2; exit 2
  fi
  chmod -R u+w "$out" && rm -rf "$out"
fi
mkdir -p "$out/scripts" "$out/scenes" "$out/datasets"
out=$(cd "$out" && pwd)
strip -o "$out/rbvh" "$rbvh" 2>/dev/null || cp "$rbvh" "$out/rbvh"
cp "$root/scripts/gpu-window.sh" "$out/scripts/"
# gpu-window.sh copies the scene files it runs, naming DATASETS_DIR in the copies.
for scene in dragon-closeup.toml paper-scale.toml dragons-1000.toml paper-scale-instanced.toml; do
  cp "$root/scenes/$scene" "$out/scenes/"
done

# The meshes those scenes read, and Sponza's materials and textures (a material's image must load).
pack() {
  local from=$datasets/$1
  if [ ! -e "$from" ]; then
    echo "left out: $from is missing" >&2
    return
  fi
  mkdir -p "$(dirname "$out/datasets/$1")"
  if [ -d "$from" ]; then
    cp -r --no-preserve=mode "$from" "$out/datasets/$1"
  else
    xz -9 -T0 -c "$from" > "$out/datasets/$1.xz"
  fi
}
pack dragon/dragon_vrip.obj
pack sponza-dabrovic/sponza.obj
pack sponza-dabrovic/sponza.mtl
pack sponza-dabrovic/textures

case ${LOADER_DEB:-} in
  none) ;;
  "") fetched=$(mktemp -d)
      (cd "$fetched" && apt-get download libvulkan1 >/dev/null 2>&1) && mv "$fetched"/libvulkan1_*.deb "$out/" \
        || echo "warning: apt-get download libvulkan1 failed: the bundle has no Vulkan loader" >&2
      rm -rf "$fetched" ;;
  *) cp "$LOADER_DEB" "$out/libvulkan1_bundled.deb" ;;
esac

quoted_commit=$(printf '%q' "$commit")
cat > "$out/run.sh" <<EOF
#!/usr/bin/env bash
# Made by scripts/gpu-bundle.sh at $commit: unpacks the datasets and, where the system has no
# Vulkan loader, the bundled one, then runs scripts/gpu-window.sh BUDGET_SECONDS over them.
set -uo pipefail
budget=\${1:?usage: run.sh BUDGET_SECONDS [RESULTS_DIR]}
here=\$(cd "\$(dirname "\$0")" && pwd)
results=\${2:-\$here/results}
# Without xz the datasets stay packed and the window skips the steps that need them.
if command -v xz >/dev/null; then
  find "\$here/datasets" -name '*.xz' -exec xz -d -k -f {} + || echo "warning: unpacking the datasets failed" >&2
else
  echo "warning: xz is missing: the datasets stay packed, and the steps that need them are skipped" >&2
fi
# The system's loader where it has one (the cache read whole: grep -q closing the pipe early would
# fail the test under pipefail); else the bundled one.
cache=\$( (ldconfig -p || /sbin/ldconfig -p) 2>/dev/null )
if ! grep -q 'libvulkan\.so\.1 ' <<<"\$cache"; then
  deb=\$(ls "\$here"/libvulkan1_*.deb 2>/dev/null | head -n 1)
  [ -n "\$deb" ] || { echo "no Vulkan loader on this machine and none bundled" >&2; exit 2; }
  mkdir -p "\$here/loader"
  if command -v dpkg-deb >/dev/null; then
    dpkg-deb -x "\$deb" "\$here/loader" || { echo "unpacking \$deb failed" >&2; exit 2; }
  else
    (cd "\$here/loader" && ar x "\$deb" && tar -xf data.tar.*) || { echo "unpacking \$deb failed" >&2; exit 2; }
  fi
  lib=\$(find "\$here/loader" -name 'libvulkan.so.1' | head -n 1)
  [ -n "\$lib" ] || { echo "\$deb holds no libvulkan.so.1" >&2; exit 2; }
  export LD_LIBRARY_PATH="\$(dirname "\$lib")\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH}"
fi
RBVH="\$here/rbvh" RBVH_COMMIT=$quoted_commit exec bash "\$here/scripts/gpu-window.sh" "\$budget" "\$results" "\$here/datasets"
EOF
chmod +x "$out/run.sh" "$out/rbvh"
echo "bundle of $commit in $out ($(du -sh "$out" | cut -f1)): copy it to the GPU machine and run $out/run.sh BUDGET_SECONDS there"
