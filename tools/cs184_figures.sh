#!/usr/bin/env bash
# Renders the CS184 comparison figures of issue 5 and a table of times and speeds.
#
#   bash tools/cs184_figures.sh OUT_DIR [SCENE...]     # SCENE: bunny spheres_lambertian spheres dragon
#
# Environment: RAYPACK (binary, default target/release/raypack), RAYPACK_SCENES (default
# ../shared/scenes), RES ("480 360"), THREADS (2), MAX_SPP (1024: cap of the -s series),
# ADAPTIVE_SPP (2048). Each render's log is kept beside its image; OUT_DIR/summary.md lists
# every render with its time and speeds.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:?usage: tools/cs184_figures.sh OUT_DIR [SCENE...]}
shift
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(bunny spheres_lambertian spheres dragon)
bin=${RAYPACK:-target/release/raypack}
root=${RAYPACK_SCENES:-../shared/scenes}
res=(${RES:-480 360})
threads=${THREADS:-2}
max_spp=${MAX_SPP:-1024}
adaptive_spp=${ADAPTIVE_SPP:-2048}
mkdir -p "$out"
summary="$out/summary.md"
[ -f "$summary" ] || printf '| image | flags | render s | Msamples/s | Mrays/s (camera / shadow / bounce) |\n|---|---|---|---|---|\n' >"$summary"

path_of() {
  case $1 in
    bunny) echo "$root/cs184/sky/CBbunny.dae" ;;
    spheres_lambertian) echo "$root/cs184/sky/CBspheres_lambertian.dae" ;;
    spheres) echo "$root/cs184/sky/CBspheres.dae" ;;
    dragon) echo "$root/models/stanford-dragon-871k.ply" ;;
    *) echo "unknown scene $1" >&2; exit 2 ;;
  esac
}

# render NAME SCENE FLAGS...: one image, its log, one summary row.
render() {
  local name=$1 scene=$2
  shift 2
  local img="$out/$name.png" log="$out/$name.log"
  "$bin" render "$scene" -t "$threads" -r "${res[@]}" "$@" -f "$img" 2>"$log"
  local secs sps kinds
  secs=$(sed -n 's/.*Rendering\.\.\. 100%! (\([0-9.]*\)s).*/\1/p' "$log")
  sps=$(sed -n 's/.*), \([0-9.]*\) million samples per second.*/\1/p' "$log")
  kinds=$(grep -E '^\[raypack\] +(camera|shadow|bounce) ' "$log" | sed -E 's/.*rays, +([0-9.]+) Mrays.*/\1/' | paste -sd/ | sed 's#/# / #g')
  printf '| %s | `%s` | %s | %s | %s |\n' "$name.png" "$*" "$secs" "$sps" "$kinds" >>"$summary"
  echo "$name: ${secs}s, ${sps} Msamples/s"
}

for s in "${scenes[@]}"; do
  f=$(path_of "$s")
  # Direct lighting: uniform hemisphere vs light sampling at the same budget (CS184 part 3).
  render "${s}_direct_H_s16_l8" "$f" --integrator direct -s 16 -l 8 -H
  render "${s}_direct_s16_l8" "$f" --integrator direct -s 16 -l 8
  # Light rays per area light with one camera ray per pixel.
  for l in 1 4 16 64; do render "${s}_direct_s1_l$l" "$f" --integrator direct -s 1 -l "$l"; done
  # Maximum ray depth (accumulated), and exactly m bounces (CS184 part 4).
  for m in 0 1 2 3 100; do render "${s}_global_m${m}" "$f" --integrator global -s 64 -l 4 -m "$m"; done
  for m in 2 3; do render "${s}_bounce_m${m}" "$f" --integrator bounce -s 64 -l 4 -m "$m"; done
  # Samples per pixel.
  for spp in 1 4 16 64 256 1024; do
    if [ "$spp" -le "$max_spp" ]; then render "${s}_global_s${spp}" "$f" --integrator global -s "$spp" -l 4 -m 5; fi
  done
  # Adaptive sampling (CS184 part 5), with its sample-rate image.
  render "${s}_adaptive" "$f" --integrator global -s "$adaptive_spp" -a 64 0.05 -l 1 -m 5
done
