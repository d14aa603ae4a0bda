#!/bin/bash
# Renders one image as a Slurm job array of N shards and a merge job that runs once all of them
# have succeeded:
#
#   tools/slurm/submit.sh N PARTS_DIR OUTPUT [gatetrace render options, --spp included]
#   tools/slurm/submit.sh 16 /shared/parts box.exr assets/scenes/cornell_box.gltf \
#       --method ellipsoidal --gate box:3.14..3.19 --spp 65536 --res 512x512
#
# PARTS_DIR and OUTPUT must be on a file system every node sees. GATETRACE names the binary
# (default: gatetrace on the PATH); extra sbatch options go in SBATCH_OPTIONS (e.g. a partition,
# --gres=gpu:1). Prints the two job ids.
set -euo pipefail
if [ $# -lt 4 ]; then
    sed -n '2,12p' "$0" >&2
    exit 2
fi
count=$1 parts=$2 output=$3
shift 3
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$parts"
parts=$(cd "$parts" && pwd)
export GATETRACE_PARTS=$parts GATETRACE=${GATETRACE:-gatetrace}
# shellcheck disable=SC2086
array=$(sbatch --parsable ${SBATCH_OPTIONS:-} --array=0-$((count - 1)) --chdir="$PWD" --export=ALL \
    --output="$parts/%x-%A_%a.out" "$here/render_shard.sbatch" "$@")
# shellcheck disable=SC2086
merge=$(sbatch --parsable ${SBATCH_OPTIONS:-} --dependency=afterok:"$array" --chdir="$PWD" --export=ALL \
    --output="$parts/%x-%j.out" "$here/merge.sbatch" "$output")
echo "shards: job array $array ($count tasks); merge: job $merge -> $output"
