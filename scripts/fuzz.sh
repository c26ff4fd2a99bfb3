#!/usr/bin/env bash
# Fuzzes every parser with libFuzzer under AddressSanitizer + UndefinedBehaviorSanitizer (issue 6;
# by hand or nightly, not in the test command). Each target starts from its seed corpus
# (fuzz/seeds/TARGET, files from the test fixtures) and runs SECONDS; new coverage is kept in
# build-fuzz/corpus/TARGET, crashes go to fuzz/findings/TARGET/ (turn each into a regression:
# move it to fuzz/regressions/TARGET/, fix, and the test suite replays it from then on).
#   scripts/fuzz.sh [SECONDS=60] [TARGET...]        e.g. scripts/fuzz.sh 60 mvei_fuzz tile_fuzz
# Prints per target: executions, coverage (edges), corpus size, crashes. Exit 1 if any crashed.
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_PER=${1:-60}
shift || true
BUILD=${BUILD:-build-fuzz}
if ! command -v clang++ > /dev/null || ! ls /usr/lib/llvm-*/lib/clang/*/lib/linux/libclang_rt.fuzzer-x86_64.a > /dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  $SUDO apt-get install -y -qq --no-install-recommends clang libclang-rt-dev > /dev/null
fi
SAN="-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer"
mkdir -p "$BUILD"
cmake -S . -B "$BUILD" -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DSCALEFUSE_FUZZ=ON -DSCALEFUSE_BUILD_TESTS=OFF -DSCALEFUSE_MPI=OFF -DCMAKE_CXX_FLAGS="$SAN" > "$BUILD/cmake.log"
TARGETS=("$@")
if [ ${#TARGETS[@]} -eq 0 ]; then
  for f in fuzz/*_fuzz.cc; do TARGETS+=("$(basename "$f" .cc)"); done
fi
cmake --build "$BUILD" -j"${JOBS:-2}" --target "${TARGETS[@]}" > "$BUILD/build.log" || { tail -40 "$BUILD/build.log"; exit 1; }
export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=0 UBSAN_OPTIONS=print_stacktrace=1
crashed=0
printf "%-22s %12s %8s %8s %8s\n" target executions "cov" corpus crashes
for t in "${TARGETS[@]}"; do
  corpus=$BUILD/corpus/$t findings=fuzz/findings/$t
  mkdir -p "$corpus" "$findings"
  [ -d "fuzz/seeds/$t" ] && cp -n fuzz/seeds/"$t"/* "$corpus"/ 2> /dev/null || true
  log=$BUILD/$t.log
  # -rss_limit_mb: a header that makes a parser allocate gigabytes is a finding, not a slow run.
  if ! "$BUILD/bin/$t" -max_total_time="$SECONDS_PER" -max_len=65536 -rss_limit_mb=2048 -timeout=20 \
      -print_final_stats=1 -artifact_prefix="$findings/" "$corpus" > "$log" 2>&1; then
    crashed=1
  fi
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo "?")
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | grep -o '[0-9]*' || echo "?")
  n=$(find "$corpus" -type f | wc -l)
  c=$(find "$findings" -type f | wc -l)
  printf "%-22s %12s %8s %8s %8s\n" "$t" "$execs" "$cov" "$n" "$c"
done
[ $crashed = 0 ] || { echo "crashes: see fuzz/findings/ and $BUILD/<target>.log"; exit 1; }
