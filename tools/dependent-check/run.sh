#!/usr/bin/env bash
# Times raypack's SIMD kernels on `raypack bench`'s ray sets (1 thread) in two builds, turn
# by turn: the project's own (`cargo build --release`, the repository's profile) and this
# dependent crate (cargo's default release profile, no RUSTFLAGS), and prints the ratio of
# their medians per set, kernel and ISA.
#
#   bash tools/dependent-check/run.sh SCENE [ROUNDS] [ISA ...]     # default: 3 rounds, every ISA the CPU has
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
scene=${1:?usage: run.sh SCENE [ROUNDS] [ISA ...]}
rounds=${2:-3}
shift $(( $# >= 2 ? 2 : 1 ))
isas=("$@")
(cd "$here/../.." && env -u RUSTFLAGS cargo build --release -q --features tools --bin dependent_kernels)
(cd "$here" && env -u RUSTFLAGS -u CARGO_ENCODED_RUSTFLAGS cargo build --release -q)
own="$here/../../target/release/dependent_kernels"
dep="$here/target/release/dependent-check"
if [ ${#isas[@]} -eq 0 ]; then
  isas=($("$own" --list-isas))
fi
out=$(mktemp -d)
for isa in "${isas[@]}"; do
  for r in $(seq "$rounds"); do
    "$own" "$scene" --isa "$isa" >> "$out/own" 
    "$dep" "$scene" --isa "$isa" >> "$out/dep"
  done
done
python3 - "$out/own" "$out/dep" <<'PY'
import sys, statistics, collections
def load(p):
    d = collections.defaultdict(list)
    for line in open(p):
        s, k, isa, m, *_ = line.split()
        d[(s, k, isa)].append(float(m))
    return d
own, dep = load(sys.argv[1]), load(sys.argv[2])
print(f"{'set':<8} {'kernel':<26} {'isa':<7} {'project':>9} {'dependent':>10} {'ratio':>6}   (median Mrays/s over rounds, 1 thread)")
for key in own:
    o, d = statistics.median(own[key]), statistics.median(dep[key])
    print(f"{key[0]:<8} {key[1]:<26} {key[2]:<7} {o:9.3f} {d:10.3f} {d/o:6.3f}")
PY
rm -rf "$out"
