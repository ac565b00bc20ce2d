#!/usr/bin/env bash
# Fetches the public CS184 / CMU 15-462 path tracer scenes (COLLADA .dae files in the
# basic/, keenan/, meshedit/ and sky/ folders of the assignments' dae/ directory) into DIR,
# for users outside the raypack workplace (which has them in ../shared/scenes/cs184).
#
#   bash tools/fetch-cs184-scenes.sh DIR          # then: RAYPACK_SCENES=... or raypack render DIR/sky/CBbunny.dae
#
# Needs git (preferred: sparse, blob-filtered clone of dae/ only) or curl + tar. Tries each
# repository below in turn until one provides dae/. Nothing here runs in the test suite.
# The scene files are third-party data: keep them out of raypack's own repository.
set -euo pipefail

if [ $# -ne 1 ]; then
  echo "usage: $0 DIR" >&2
  exit 2
fi
dest=$1
mkdir -p "$dest"

# Public repositories that carry the assignment's dae/ folder (the course repositories
# themselves are private per semester; these are public forks of the starter code).
repos=(
  Khrylx/DSGPURayTracing
  wanghaodawn/Ray-Path-Tracer
  hilary217/cs184-final
)

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

fetch_git() {
  local repo=$1 dir=$tmp/git
  rm -rf "$dir"
  command -v git >/dev/null || return 1
  git clone --quiet --depth 1 --filter=blob:none --sparse "https://github.com/$repo.git" "$dir" || return 1
  git -C "$dir" sparse-checkout set dae || return 1
  [ -d "$dir/dae" ] || return 1
  cp -R "$dir/dae/." "$dest/"
}

fetch_tarball() {
  local repo=$1 dir=$tmp/tar
  rm -rf "$dir" && mkdir -p "$dir"
  command -v curl >/dev/null || return 1
  curl -fsSL "https://codeload.github.com/$repo/tar.gz/HEAD" | tar -xz -C "$dir" --wildcards '*/dae/*' || return 1
  local src
  src=$(find "$dir" -mindepth 2 -maxdepth 2 -type d -name dae | head -n 1)
  [ -n "$src" ] || return 1
  cp -R "$src/." "$dest/"
}

for repo in "${repos[@]}"; do
  echo "fetch-cs184-scenes: trying $repo" >&2
  if fetch_git "$repo" || fetch_tarball "$repo"; then
    count=$(find "$dest" -name '*.dae' | wc -l)
    echo "fetch-cs184-scenes: $count .dae files from $repo in $dest" >&2
    exit 0
  fi
done
echo "fetch-cs184-scenes: none of ${repos[*]} could be fetched (no network?)" >&2
exit 1
