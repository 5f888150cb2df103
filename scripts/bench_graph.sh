#!/usr/bin/env bash
# Benchmark: the paper scenario (Singapore, 10 requests per 30 s, 3500 s) through the whole node
# graph in lockstep, recorded to MCAP and .rrd. Prints the real-time factor and where the time
# goes (CPU seconds of each node process). Extra arguments go to run_fleet.sh (e.g. --rerun off).
set -Eeuo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
if [[ "${1:-}" == "-h" || "${1:-}" == "--help" ]]; then
  sed -n '2,4p' "$0" | sed 's/^# \{0,1\}//'; echo "usage: scripts/bench_graph.sh [run_fleet.sh options, e.g. --rerun off]"; exit 0
fi
OUT="${BENCH_OUT:-/tmp/uam-bench-graph}"
rm -rf "$OUT"
bash scripts/run_fleet.sh --duration 3500 --rate 10 --backend exact --out "$OUT" "$@" > "$OUT.log" 2>&1 || {
  tail -n 30 "$OUT.log"; echo "bench_graph: the run failed" >&2; exit 1; }
echo "machine: $(lscpu | sed -n 's/^Model name: *//p'), $(nproc) cores; load average $(cut -d' ' -f1-3 /proc/loadavg)"
echo "commit:  $(git rev-parse --short HEAD 2>/dev/null || echo unknown)"
grep -h "run finished" "$OUT/simulator.log" | sed 's/^.*run finished/simulator: run finished/'
echo
echo "where the time goes (CPU seconds per process, from each node's exit report):"
grep -h "process cpu" "$OUT"/*.log | sed 's/^/  /'
grep -E "^(Requests|  approved|  expired|Active aircraft|Solve time|Safety audit)" "$OUT/summary.txt" | sed 's/^/  /'
