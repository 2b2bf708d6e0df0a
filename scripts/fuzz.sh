#!/usr/bin/env bash
# Fuzz octocd's loaders with libFuzzer (issues 10, 22): the scene loader, the mesh loader
# (OFF/OBJ/PLY through assimp and octocd's checks), the trace readers (summary, XDMF,
# TraceReader), `compare` and `replay` (the commands, on the fuzzed trace) and the
# external-trace reader of `validate --trace-in` (check and 3 frames judged), and (issue 36)
# the report's inputs and the Python reader: report (a trace through `trace-summary --json`,
# the report's only way to read one, its JSON checked as make_report.py takes it), pytrace
# (octocd.Trace's calls through the C++ functions the module binds, fuzz/fuzz_pytrace.cpp
# says why), report-json (the bench-result JSON make_report.py reads: a Python driver,
# scripts/fuzz_report_json.py, in /usr/bin/python3: no sanitizer applies to Python), and
# (issue 57) the JSON readers of octocd: expect (the --expect reader), shards (the shard
# reader of validate --merge), bench_result (the result reader of bench --resume), and
# (issue 68) sinks (the escaping of untrusted text for the terminal, CSV and JSON).
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]
#       TARGET: scene mesh trace compare replay external report pytrace report-json expect
#               shards bench_result sinks (default: all thirteen)
#
# Builds build-fuzz/ (CMake preset "fuzz": clang, ASan + UBSan, -fsanitize=fuzzer), makes
# a seed corpus from the shipped files (datasets/scenes, tests/data, fuzz/regressions, a
# small trace written by octocd), then runs each target for SECONDS (default 600) one after
# the other under `nice`, on one core. Work and crash artifacts go to fuzz/work/<target>/
# (ignored by git). A crash is printed with the command that reproduces it; once fixed,
# copy the input into fuzz/regressions/<target>/, where ctest replays it in every build
# (fuzz.<target>.regressions, label unit); fuzz/regressions/trace/ is replayed by every
# trace-reading target (trace, compare, replay, external) and seeds all of them.
#
# Needs clang and libFuzzer from Debian: apt-get install clang (libclang-rt-14-dev).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-600}
shift || true
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(scene mesh trace compare replay external report pytrace report-json expect shards
                                     bench_result sinks)
libfuzzer=()
for t in "${targets[@]}"; do [ "$t" != report-json ] && libfuzzer+=("$t"); done

command -v clang++ >/dev/null || { echo "fuzz.sh: clang++ not found; apt-get install clang" >&2; exit 2; }

cmake --preset fuzz >/dev/null
[ ${#libfuzzer[@]} -gt 0 ] && nice -n 10 cmake --build build-fuzz -j2 --target "${libfuzzer[@]/#/fuzz_}"

work=fuzz/work
for t in "${targets[@]}"; do
  mkdir -p "$work/$t/corpus" "$work/$t/artifacts"
  cp -n fuzz/regressions/"$t"/* "$work/$t/corpus/" 2>/dev/null || true
  case $t in
    compare|replay|external|report|pytrace) cp -n fuzz/regressions/trace/* "$work/$t/corpus/" ;;
    report-json) cp -n tests/data/bench-small-*.json tests/data/gate-*.json "$work/$t/corpus/" ;;
    expect) cp -n scripts/nightly-expect.json "$work/$t/corpus/" ;;
  esac
done
# Seeds from the shipped files.
for t in "${targets[@]}"; do
  case $t in
    scene) cp -n datasets/scenes/*.json tests/data/*.json "$work/scene/corpus/" ;;
    mesh)  cp -n tests/data/*.obj "$work/mesh/corpus/" ;;
    sinks) ;;  # seeds: fuzz/regressions/sinks/ (escape sequences, formulas, cut UTF-8, a long line)
    report-json|expect|shards|bench_result) ;;  # seeds: fuzz/regressions/<t>/ (scripts/fuzz_json_seeds.py)
    trace|compare|replay|external|report|pytrace)
           if [ ! -f "$work/$t/corpus/box-stack-20.h5" ]; then
             [ -x build/octocd ] || { echo "fuzz.sh: build/octocd is needed for the trace seeds" >&2; exit 2; }
             ./build/octocd run datasets/scenes/box-stack.json --frames 20 --state-every 5 --contacts \
               --trace "$work/$t/corpus/box-stack-20.h5" --quiet --no-xdmf
             ./build/octocd run tests/data/spheres-drop.json --frames 10 --state-every 10 \
               --trace "$work/$t/corpus/spheres-10.h5" --quiet --no-xdmf || true
           fi
           # External traces (docs/trace-format.md), versions 1 and 2, from the examples.
           if [ "$t" = external ] && [ ! -f "$work/$t/corpus/toy-v1.h5" ]; then
             /usr/bin/python3 examples/python/toy_engine.py "$work/$t/corpus/toy-v1.h5" >/dev/null || true
             /usr/bin/python3 examples/python/rotating_writer.py "$work/$t/corpus/rotating-v2.h5" >/dev/null || true
           fi ;;
    *) echo "fuzz.sh: unknown target '$t'; allowed: scene mesh trace compare replay external report pytrace" \
            "report-json expect shards bench_result sinks" >&2; exit 2 ;;
  esac
done

status=0
for t in "${targets[@]}"; do
  echo "== fuzz_$t: ${seconds} s"
  if [ "$t" = report-json ]; then
    [ -x build/octocd ] || { echo "fuzz.sh: build/octocd is needed for report-json" >&2; exit 2; }
    if ! nice -n 15 /usr/bin/python3 scripts/fuzz_report_json.py "$seconds" "$work/$t" build/octocd \
          "$work/$t"/corpus/* fuzz/regressions/report-json/* >"$work/$t/log.txt" 2>&1; then
      status=1
      echo "report-json found a crash:"; grep finding "$work/$t/log.txt" | head -5
    fi
    grep "stat::" "$work/$t/log.txt" || true
    continue
  fi
  dict=()
  [ "$t" = scene ] && dict=(-dict=fuzz/scene.dict)
  [ "$t" = mesh ] && dict=(-dict=fuzz/mesh.dict)
  max_len=65536
  case $t in  # a trace is >= 200 KB (full chunks of /frames)
    trace|compare|replay|external|report|pytrace) max_len=300000 ;;
  esac
  # assimp 5.2 and libhdf5 1.10.8 leak on some malformed files they reject (upstream; the
  # inputs are in fuzz/upstream/): leaks are not findings for the mesh and trace targets.
  leaks=0
  case $t in scene|expect|shards|bench_result|sinks) leaks=1 ;; esac  # octocd's own code only: a leak is a finding
  if ! ASAN_OPTIONS="detect_leaks=$leaks" nice -n 15 ./build-fuzz/fuzz_"$t" "$work/$t/corpus" "${dict[@]}" \
        -max_total_time="$seconds" -timeout=20 -rss_limit_mb=4096 -max_len="$max_len" \
        -artifact_prefix="$work/$t/artifacts/" -print_final_stats=1 -close_fd_mask=1 2>"$work/$t/log.txt"; then
    status=1
    echo "fuzz_$t found a crash:"; grep -E "ERROR|SUMMARY|Test unit written" "$work/$t/log.txt" | head -5
    echo "reproduce: ./build-fuzz/fuzz_$t $work/$t/artifacts/<crash-file>"
  fi
  tail -n 12 "$work/$t/log.txt" | grep -E "stat::|Done" || true
done
exit $status
