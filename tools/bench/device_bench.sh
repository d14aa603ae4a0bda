#!/usr/bin/env bash
# The device benchmark: samples per second of every method, GPU time per stage and a short
# equal-time comparison on whatever GPU the machine has, in one JSON file.
#
#   tools/bench/device_bench.sh [--exe PATH] [--out FILE.json] [--seconds S] [--smoke]
#                               [--peer-variant V] [--peer-seconds S]
#
# It builds nothing: it runs a release binary built on another machine (default
# target/release/gatetrace; copy it over with the repository) and needs only a Vulkan loader and
# driver, and python3 (standard library only) to make the test meshes and write the JSON. On a
# GPU it ends within 8 minutes.
#
# Scenes: the Cornell box, and the displaced spheres of 327,680 and 1,310,720 triangles in the
# box (tools/scenes/make_sphere_scene.py; made in target/scenes when missing). For each scene:
#   - `gatetrace bench` (path, direct, ellipsoidal at the 2.5 mm gate, and ellipsoidal:wide, its
#     queries over the wide BVH; 64x64, 5 bounces) for --seconds each: samples/s, set-up time,
#     the scene's load and BVH build time;
#   - the same with --profile for a second each: GPU time per stage (ms);
#   - `gatetrace equal-time` of direct, ellipsoidal and ellipsoidal:wide at the 2.5 mm gate: MSE
#     at equal time against a reference render.
# Then `gatetrace bench` on the largest mesh at larger images (256x256 and 1024x1024, 2 s
# each): a GPU keeps more paths in flight than a 64x64 image gives it.
# Then `gatetrace bench` on the largest mesh at the first image size with several samples per
# pass (a pass of K samples of a WxH image fills W*H*K path slots: the wave a GPU keeps in
# flight), for the bidirectional methods, whose per-slot state bounds their waves on a GPU; a
# pass too large for the device's bindings is reported as skipped.
# Where Python can import mitsuba and mitransient with Mitsuba's variant --peer-variant (default
# cuda_ad_rgb), tools/peer/throughput.py then measures the peer and every method side by side on
# the same scenes (--peer-seconds each, default 4, 0.3 with --smoke); the JSON's "peer" holds
# that, or why not.
# --smoke runs the same on the Cornell box and a sphere of 1,280 triangles at 16x16 (one larger
# image of 32x32; passes of 1, 2 and 100,000 samples, the last too large) for a fraction of a
# second each (the test suite runs it on lavapipe: tests/device_bench.rs).
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/../.." && pwd)"
exe="$ROOT/target/release/gatetrace"
out="device_bench.json"
seconds=8
smoke=0
peer_variant=cuda_ad_rgb
peer_seconds=
while [ $# -gt 0 ]; do
    case "$1" in
        --exe) exe="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --seconds) seconds="$2"; shift 2 ;;
        --smoke) smoke=1; shift ;;
        --peer-variant) peer_variant="$2"; shift 2 ;;
        --peer-seconds) peer_seconds="$2"; shift 2 ;;
        -h|--help) sed -n '2,33p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "device_bench.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done
if [ ! -x "$exe" ]; then
    echo "device_bench.sh: no gatetrace binary at $exe: build one with 'cargo build --release' (on any machine) and pass it with --exe" >&2
    exit 2
fi
command -v python3 >/dev/null || { echo "device_bench.sh: python3 is needed (meshes, JSON)" >&2; exit 2; }

scenes_dir="$ROOT/target/scenes"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
if [ "$smoke" = 1 ]; then
    res=16x16
    profile_seconds=0.2
    equal_seconds=0.3
    reference_seconds=1
    peer_seconds="${peer_seconds:-0.3}"
    large_resolutions=(32x32)
    large_seconds=0.2
    wave_samples=1,2,100000
    frequencies=(8)
    scenes_dir="$work"
else
    res=64x64
    profile_seconds=1
    equal_seconds=4
    reference_seconds=24
    peer_seconds="${peer_seconds:-4}"
    large_resolutions=(256x256 1024x1024)
    large_seconds=2
    wave_samples=16,32,64,128
    frequencies=(128 256)
fi
scenes=("$ROOT/assets/scenes/cornell_box.gltf")
mkdir -p "$scenes_dir"
for f in "${frequencies[@]}"; do
    mesh="$scenes_dir/sphere_$((20 * f * f)).glb"
    if [ ! -f "$mesh" ]; then
        python3 "$ROOT/tools/scenes/make_sphere_scene.py" --frequency "$f" --out "$mesh" >&2
    fi
    scenes+=("$mesh")
done

gate='box:3.16..3.1625'
methods=path,direct,ellipsoidal,ellipsoidal:wide
i=0
for scene in "${scenes[@]}"; do
    echo "device_bench: $(basename "$scene")" >&2
    "$exe" bench --scene "$scene" --methods "$methods" --seconds "$seconds" --res "$res" --json "$work/bench_$i.json" >&2
    "$exe" bench --scene "$scene" --methods "$methods" --seconds "$profile_seconds" --res "$res" --profile \
        --json "$work/profile_$i.json" >&2
    "$exe" equal-time "$scene" --methods direct,ellipsoidal,ellipsoidal:wide --gates "$gate" --seconds "$equal_seconds" --repeats 1 \
        --reference-method ellipsoidal --reference-seconds "$reference_seconds" --res "$res" --csv "$work/equal_$i.csv" >&2
    i=$((i + 1))
done

j=0
for r in "${large_resolutions[@]}"; do
    echo "device_bench: $(basename "${scenes[-1]}") at $r" >&2
    "$exe" bench --scene "${scenes[-1]}" --methods "$methods" --seconds "$large_seconds" --res "$r" \
        --json "$work/large_$j.json" >&2
    j=$((j + 1))
done

echo "device_bench: $(basename "${scenes[-1]}") at $res with $wave_samples samples per pass" >&2
"$exe" bench --scene "${scenes[-1]}" --methods direct,ellipsoidal,ellipsoidal:wide --seconds "$large_seconds" \
    --res "$res" --samples-per-pass "$wave_samples" --json "$work/waves.json" >&2

# The peer, side by side with every method, where its Python packages and variant load.
if why=$(python3 -c "import mitsuba as mi; mi.set_variant('$peer_variant'); import mitransient" 2>&1); then
    echo "device_bench: the peer ($peer_variant) on every scene" >&2
    scene_args=()
    for scene in "${scenes[@]}"; do scene_args+=(--scene "$scene"); done
    python3 "$ROOT/tools/peer/throughput.py" "${scene_args[@]}" --seconds "$peer_seconds" --res "${res%%x*}" \
        --peer-variant "$peer_variant" --exe "$exe" --json "$work/peer.json" >&2
else
    echo "device_bench: the peer is not measured: mitsuba, mitransient or variant $peer_variant does not load" >&2
    printf '%s\n' "$why" | tail -1 | python3 -c 'import json, sys; json.dump({"skipped": sys.stdin.read().strip()}, open(sys.argv[1], "w"))' "$work/peer.json"
fi

python3 - "$work" "$i" "$out" "$seconds" "$smoke" "$j" <<'EOF'
import csv, json, sys
work, count, out, seconds, smoke = sys.argv[1], int(sys.argv[2]), sys.argv[3], float(sys.argv[4]), sys.argv[5] == "1"
large_count = int(sys.argv[6])
scenes = []
for i in range(count):
    bench = json.load(open(f"{work}/bench_{i}.json"))
    profile = json.load(open(f"{work}/profile_{i}.json"))
    stages = {m["method"]: m["stages"] for m in profile["measurements"]}
    for m in bench["measurements"]:
        m["stages"] = stages.get(m["method"], [])
    with open(f"{work}/equal_{i}.csv") as f:
        equal = list(csv.DictReader(f))
    scenes.append({
        "scene": bench["scene"],
        "triangles": bench["triangles"],
        "load_and_build_seconds": bench["load_and_build_seconds"],
        "measurements": bench["measurements"],
        "equal_time": equal,
    })
first = json.load(open(f"{work}/bench_0.json"))
report = {
    "adapter": first["adapter"],
    "backend": first["backend"],
    "device_type": first["device_type"],
    "driver": first["driver"],
    "driver_info": first["driver_info"],
    "smoke": smoke,
    "seconds_per_measurement": seconds,
    "max_bounces": first["max_bounces"],
    "scenes": scenes,
    "larger_images": [json.load(open(f"{work}/large_{j}.json")) for j in range(large_count)],
    "waves": json.load(open(f"{work}/waves.json")),
    "peer": json.load(open(f"{work}/peer.json")),
}
with open(out, "w") as f:
    json.dump(report, f, indent=2)
    f.write("\n")
print(f"device_bench: {report['adapter']} ({report['device_type']}): wrote {out}", file=sys.stderr)
for s in scenes:
    rates = ", ".join(f"{m['method']} {m['samples_per_second'] / 1e6:.3f}" for m in s["measurements"])
    print(f"  {s['scene'].split('/')[-1]} ({s['triangles']} triangles): M samples/s {rates}", file=sys.stderr)
for b in report["larger_images"]:
    rates = ", ".join(f"{m['method']} {m['samples_per_second'] / 1e6:.3f}" for m in b["measurements"])
    size = f"{b['measurements'][0]['width']}x{b['measurements'][0]['height']}"
    print(f"  {b['scene'].split('/')[-1]} at {size}: M samples/s {rates}", file=sys.stderr)
for m in report["waves"]["measurements"]:
    rate = f"{m['samples_per_second'] / 1e6:.3f} M samples/s" if "samples_per_second" in m else "skipped"
    print(f"  waves: {m['method']} {m['samples_per_pass']} samples per pass: {rate}", file=sys.stderr)
for s in report["peer"].get("scenes", []):
    ratios = ", ".join(f"{m['method']} {m['per_peer']:.2f}x" for m in s["measurements"] if m["per_peer"])
    print(f"  {s['scene']}: against the peer {ratios}", file=sys.stderr)
EOF
