#!/usr/bin/env bash
# The live path's latency harness (issue: the live runtime). Builds what it needs (release preset),
# builds the SMPL rig from ../shared/data once (human_man.obj bound to the 41 markers of the HDM05
# clip, the BM_RigFrame/smpl_hdm05 rig), then runs the clip at its own 120 Hz pace through
# `tetrig run` (driver thread -> mailbox -> solver thread -> shared memory) with `tetrig-shm-cat`
# reading the segment in another process. Before that, tetrig_host_probe (10 s) measures what the
# host gives a 120 Hz loop doing fixed work (bench/tools/host_probe.cpp). Writes
# build/release/latency.json (the keys of `tetrig run --stats-json`, plus "consumer" and
# "host_probe") and prints the table.
#
#   bash bench/latency.sh                 # SMPL + HDM05 (the figure of record)
#   bash bench/latency.sh --synthetic     # the same rig driven by the synthetic source (10 s)
#   bash bench/latency.sh --armadillo     # the Stanford Armadillo rig driven by the HDM05 clip
#   bash bench/latency.sh --cap 48        # the SMPL rig with B capped at 48 entries per row (whole
#                                         # tets, renormalised; accuracy cost in docs/live.md)
#   bash bench/latency.sh --iterations 1  # iterations per frame (default 3)
#   bash bench/latency.sh --performers 2  # one performer, then N performers (the same clip read once and
#                                         # fanned out, one solver thread and segment each, one consumer
#                                         # per segment) in the same invocation: the table per performer
#                                         # and the ratio of their p99 to the single performer's
#   bash bench/latency.sh --dds           # also over Cyclone DDS (tetrig run --dds, tetrig-dds-cat in another
#                                         # process, loopback only: dds/config/loopback.xml unless CYCLONEDDS_URI
#                                         # is set); the DDS subscriber's figures beside the segment consumer's
#   extra arguments after -- go to `tetrig run` (e.g. -- --cpu 1 --fifo, or -- --keep-volume)
set -euo pipefail
cd "$(dirname "$0")/.."
data="${TETRIG_DATA_DIR:-../shared/data}"
mode=smpl
cap=0
performers=1
iterations=3
dds=0
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --synthetic) mode=synthetic ;;
    --armadillo) mode=armadillo ;;
    --cap) shift; cap="${1:?--cap needs a number}" ;;
    --iterations) shift; iterations="${1:?--iterations needs a number}" ;;
    --performers) shift; performers="${1:?--performers needs a number}" ;;
    --dds) dds=1 ;;
    --) shift; extra=("$@"); break ;;
    *) echo "latency.sh: unknown argument $1 (use --synthetic, --armadillo, --cap N, --iterations N, --performers N, --dds, or -- ARGS for tetrig run)" >&2; exit 2 ;;
  esac
  shift
done
clip="$data/mocap/hdm05/HDM_mm_01-02_03_120.c3d"
for f in "$clip" "$data/meshes/odedstein-meshes/human_man.obj"; do
  [ -f "$f" ] || { echo "latency.sh: $f not found (place ../shared/data beside the checkout or set TETRIG_DATA_DIR)" >&2; exit 1; }
done
targets=(tetrig tetrig-shm-cat tetrig_pose_cap_error tetrig_host_probe)
[ "$dds" = 1 ] && targets+=(tetrig-dds-cat)
if [ ! -x build/release/tetrig ] || [ ! -x build/release/tetrig-shm-cat ] || [ ! -x build/release/tetrig_host_probe ] || [ "${LATENCY_REBUILD:-1}" = 1 ]; then
  cmake --preset release >/dev/null
  cmake --build --preset release --target "${targets[@]}" >/dev/null
fi
out=build/release
# A rig built by an older tetrig is built again: the builder's output changes with its code, and a
# stale rig measures another rig.
current() { [ -f "$1" ] && [ "$1" -nt build/release/tetrig ]; }
case "$mode" in
  smpl|synthetic)
    rig="$out/latency_smpl_hdm05.rig"
    desc=()
    if [ "$cap" != 0 ]; then
      rig="$out/latency_smpl_hdm05_cap$cap.rig"
      echo "{\"pose_transfer\": {\"max_nonzeros_per_row\": $cap}}" > "$out/latency_cap$cap.json"
      desc=(--rig "$out/latency_cap$cap.json")
      full="$out/latency_smpl_hdm05.rig"
      current "$full" || build/release/tetrig build-rig --mesh "$data/meshes/odedstein-meshes/human_man.obj" --markers "$clip" \
        --tet-vertices 1500 --max-marker-distance 0.15 --out "$full" --quiet
    fi
    current "$rig" || build/release/tetrig build-rig --mesh "$data/meshes/odedstein-meshes/human_man.obj" --markers "$clip" \
      --tet-vertices 1500 --max-marker-distance 0.15 "${desc[@]}" --out "$rig" --quiet
    ;;
  armadillo)
    rig="$out/latency_armadillo_hdm05.rig"
    current "$rig" || build/release/tetrig build-rig --mesh "$data/meshes/libigl-tutorial-data/armadillo.obj" --markers "$clip" \
      --tet-vertices 1700 --max-marker-distance 1.0 --accept-implausible-alignment --out "$rig" --quiet
    ;;
esac
source="c3d:$clip"
frames=()
if [ "$mode" = synthetic ]; then source=synthetic; frames=(--frames 1200); fi
name="tetrig-latency-$$"
rm -f "$out/latency_producer.json" "$out/latency_consumer.json" "$out/latency_host.json" "$out/latency_dds.json"
# First what the host itself gives a 120 Hz loop (10 s): the same fixed work at p50 and p99.
build/release/tetrig_host_probe --frames 1200 --rate 120 --work-us 700 --json "$out/latency_host.json"
build/release/tetrig-shm-cat "$name" --quiet --timeout-ms 20000 --json "$out/latency_consumer.json" &
consumer=$!
dds_flag=()
if [ "$dds" = 1 ]; then
  export CYCLONEDDS_URI="${CYCLONEDDS_URI:-file://$PWD/dds/config/loopback.xml}"
  build/release/tetrig-dds-cat "$name" --quiet --timeout-ms 20000 --latency-json "$out/latency_dds.json" &
  dds_consumer=$!
  dds_flag=(--dds)
  sleep 0.5  # the subscriber's participant is up before the first frame
fi
build/release/tetrig run --rig "$rig" --source "$source" --publish "$name" --iterations "$iterations" \
  --stats-json "$out/latency_producer.json" "${dds_flag[@]}" "${frames[@]}" "${extra[@]}"
wait "$consumer" || { echo "latency.sh: the consumer failed" >&2; exit 1; }
if [ "$dds" = 1 ]; then wait "$dds_consumer" || { echo "latency.sh: the DDS subscriber failed" >&2; exit 1; }; fi
if [ "$cap" != 0 ]; then
  echo "accuracy of the capped B against the full one (metres):"
  build/release/tetrig_pose_cap_error "$full" "$rig" "$clip"
fi
python3 - "$out/latency_producer.json" "$out/latency_consumer.json" "$out/latency.json" "$mode" "$out/latency_host.json" "$iterations" "$out/latency_dds.json" <<'PY'
import json, os, sys
producer, consumer, out, mode, host, iterations, dds_file = sys.argv[1:8]
p = json.load(open(producer)); c = json.load(open(consumer)); h = json.load(open(host))
d = json.load(open(dds_file)) if os.path.exists(dds_file) else None
p["consumer"] = c
if d: p["dds_subscriber"] = d
p["host_probe"] = h
p["harness"] = mode
json.dump(p, open(out, "w"), indent=2)
lat = p["latency_us"]
rows = [("receive -> taken by the solver", lat["receive_to_taken"]),
        ("receive -> step done", lat["receive_to_step_done"]),
        ("receive -> pose transfer done", lat["receive_to_pose_done"]),
        ("receive -> published", lat["receive_to_published"])]
seen = c.get("latency_us", {}).get("receive_to_seen")
if seen: rows.append(("receive -> seen by the consumer", seen))
if d:
  rows.append(("receive -> seen by the DDS subscriber", d["latency_us"]["receive_to_seen"]))
  rows.append(("published -> seen by the DDS subscriber", d["latency_us"]["published_to_seen"]))
rows += [(f"step ({iterations} iterations)", lat["step"]), ("pose transfer", lat["pose_transfer"]),
         ("overhead (published - step - pose)", lat["overhead"])]
after = lat.get("prepare_next")
if after and after["count"]: rows.append(("after publishing (prepareNextFrame: --keep-volume, --after-publish-iterations)", after))
print(f"\nlatency harness ({mode}): {p['frames']} frames of {p['source']['description']}")
print(f"rig: {p['rig']['name']}: {p['rig']['tet_vertices']} tet vertices, {p['rig']['tets']} tets, {p['rig']['fine_vertices']} fine vertices")
print("| phase | p50 (us) | p99 (us) | max (us) |\n|---|---|---|---|")
for name, r in rows: print(f"| {name} | {r['p50']:.1f} | {r['p99']:.1f} | {r['max']:.1f} |")
print(f"\nbudget misses {p['budget_misses']} (budget {p['budget_ms']:.2f} ms), frames dropped {p['dropped_frames']}, "
      f"consumer saw {c.get('frames_seen', '?')} frames, missed {c.get('frames_missed', '?')}")
print(f"solver thread: {p['solver_thread']}")
if d:
  w = p.get("dds", {})
  fps = d["frames_seen"] / d["seconds"] if d["seconds"] > 0 else 0
  print(f"DDS: {w.get('frames_written', '?')} frames written ({w.get('frames_skipped', '?')} skipped for a newer one, "
        f"{w.get('write_errors', '?')} write errors); the subscriber saw {d['frames_seen']}, missed {d['frames_missed']}, refused "
        f"{d['frames_refused']}; {d['bytes_per_frame']} bytes per frame, {d['bytes_per_frame'] * p['frames'] / max(p['seconds'], 1e-9) / 1e6:.2f} MB/s")
  s99, d99 = (seen or {}).get("p99"), d["latency_us"]["receive_to_seen"]["p99"]
  if s99 is not None and d99 is not None:
    print(f"receive -> seen p99: DDS {d99:.1f} us, segment {s99:.1f} us: DDS {d99 - s99:+.1f} us")
hw = h["workload_us"]
print(f"host probe: a fixed {h['work_us']} us workload at {h['rate_hz']} Hz took p50 / p99 / max {hw['p50']:.0f} / {hw['p99']:.0f} / {hw['max']:.0f} us "
      f"(wake-up lateness p99 {h['wake_lateness_us']['p99']:.0f} us): a p99 far above the p50 is the host, not tetrig")
print(f"wrote {out}")
PY
[ "$performers" -gt 1 ] || exit 0

# N performers: the same source for each (opened once, its frames fanned out), one segment and one
# consumer per performer.
run_args=()
consumers=()
for k in $(seq 1 "$performers"); do
  seg="$name-p$k"
  run_args+=(--performer "rig=$rig,source=$source,publish=$seg,name=p$k")
  rm -f "$out/latency_consumer_p$k.json"
  build/release/tetrig-shm-cat "$seg" --quiet --timeout-ms 20000 --json "$out/latency_consumer_p$k.json" &
  consumers+=($!)
done
build/release/tetrig run "${run_args[@]}" --iterations "$iterations" --stats-json "$out/latency_performers_producer.json" \
  "${frames[@]}" "${extra[@]}"
for c in "${consumers[@]}"; do wait "$c" || { echo "latency.sh: a consumer failed" >&2; exit 1; }; done
python3 - "$out" "$performers" <<'PY'
import json, sys
out, n = sys.argv[1], int(sys.argv[2])
single = json.load(open(f"{out}/latency.json"))
stage = json.load(open(f"{out}/latency_performers_producer.json"))
for k, p in enumerate(stage["performers"], 1):
    p["consumer"] = json.load(open(f"{out}/latency_consumer_p{k}.json"))
stage["single"] = {"latency_us": single["latency_us"], "consumer": single["consumer"], "budget_misses": single["budget_misses"]}
json.dump(stage, open(f"{out}/latency_performers.json", "w"), indent=2)
ref = single["latency_us"]["receive_to_published"]
print(f"\n{n} performers (the same clip fanned out), receive -> published and -> seen by each performer's consumer, us:")
print("| performer | CPU | published p50 | p99 | max | seen p50 | p99 | max | budget misses | dropped | p99 / one performer's |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
s = single["latency_us"]; sc = single["consumer"].get("latency_us", {}).get("receive_to_seen", {})
print(f"| one performer (above) | - | {ref['p50']:.0f} | {ref['p99']:.0f} | {ref['max']:.0f} | {sc.get('p50', 0):.0f} | {sc.get('p99', 0):.0f} | "
      f"{sc.get('max', 0):.0f} | {single['budget_misses']} | {single.get('dropped_frames', 0)} | 1.00 |")
for p in stage["performers"]:
    r = p["latency_us"]["receive_to_published"]; c = p["consumer"].get("latency_us", {}).get("receive_to_seen", {})
    print(f"| {p['name']} | {p['cpu']} | {r['p50']:.0f} | {r['p99']:.0f} | {r['max']:.0f} | {c.get('p50', 0):.0f} | {c.get('p99', 0):.0f} | "
          f"{c.get('max', 0):.0f} | {p['budget_misses']} | {p['dropped_frames']} | {r['p99'] / ref['p99']:.2f} |")
t = stage["totals"]
print(f"totals: {t['frames']} frames, {t['budget_misses']} budget misses; wrote {out}/latency_performers.json")
PY
