#!/usr/bin/env bash
# A render split over a Slurm job array: each task renders one part of the image
# (`raypack render --tile I/N`), and a job that waits for the array merges the parts into
# the whole image (`raypack merge`), the same file, byte for byte, as one render of it.
#
#   jid=$(sbatch --parsable --array=0-15 tools/slurm/render-array.sh SCENE OUT.exr [render flags])
#   sbatch --dependency=afterok:$jid tools/slurm/render-array.sh --merge OUT.exr
#
# Parts go to OUT's name with `.parts/` (OUT.exr -> OUT.parts/part-I.exr); OUT may end in
# .exr or .png. Each task uses the CPUs Slurm gives it (--cpus-per-task). A failed task
# leaves a hole that `--merge` names, with the --pixel-bounds that render it; rerun the task
# (sbatch --array=I ...) and merge again. RAYPACK names the raypack binary (default: on PATH).
# Without Slurm, set the two variables by hand (the README's loop does).
#
#SBATCH --job-name=raypack
#SBATCH --cpus-per-task=8
#SBATCH --time=02:00:00
set -euo pipefail

raypack="${RAYPACK:-raypack}"
usage="usage: sbatch --array=0-(N-1) $0 SCENE OUT.exr [raypack render flags]; then $0 --merge OUT.exr"

if [ "${1:-}" = "--merge" ]; then
  [ $# -eq 2 ] || { echo "$usage" >&2; exit 2; }
  out="$2"
  parts="${out%.*}.parts"
  shopt -s nullglob
  files=("$parts"/part-*.exr)
  [ ${#files[@]} -gt 0 ] || { echo "$0: no parts in $parts/ (did the array run?)" >&2; exit 2; }
  exec "$raypack" merge "${files[@]}" -o "$out"
fi

[ $# -ge 2 ] || { echo "$usage" >&2; exit 2; }
scene="$1"
out="$2"
shift 2
: "${SLURM_ARRAY_TASK_ID:?not a job array task: $usage}"
: "${SLURM_ARRAY_TASK_COUNT:?not a job array task: $usage}"
# Tasks numbered from SLURM_ARRAY_TASK_MIN (--array=1-16 works as well as 0-15).
part=$((SLURM_ARRAY_TASK_ID - ${SLURM_ARRAY_TASK_MIN:-0}))
parts="${out%.*}.parts"
mkdir -p "$parts"
threads=()
if [ -n "${SLURM_CPUS_PER_TASK:-}" ]; then threads=(-t "$SLURM_CPUS_PER_TASK"); fi
exec "$raypack" render "$scene" --tile "$part/$SLURM_ARRAY_TASK_COUNT" "${threads[@]}" -q "$@" -o "$parts/part-$part.exr"
