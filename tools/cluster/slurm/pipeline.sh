#!/usr/bin/env bash
# Submits ltm's sharded bake and compress of one scene to Slurm.
set -euo pipefail

usage() {
    cat <<'EOF'
Usage: pipeline.sh [OPTIONS] --work DIR SCENE

Submits the whole pipeline of SCENE as Slurm jobs chained with
--dependency=afterok (see tools/cluster/slurm/README.md):

  bake (array) → merge → analyze (array) → plan → code 1 (array) → check 1

Check K runs `ltm plan` on the analyses and coding K's parts: on "code" it
submits code K+1 (array) and check K+1; on "assemble" it runs
`ltm assemble` into DIR/scene.ltm. Array tasks use `--shard auto`.

Outputs: DIR/scene.raw (byte-identical to `ltm bake SCENE`) and
DIR/scene.ltm (byte-identical to `ltm compress scene.raw`, with the same
options); parts under DIR/bake, DIR/analyze, DIR/code; logs under
DIR/logs; the job ids in DIR/jobs. Prints the job ids; wait for the end with
`wait.sh DIR`.

Options:
  --work DIR          Work directory on storage every node shares (created)
  --shards N          Tasks per array: shards of the bake and the compress (default 4)
  --ltm PATH          The ltm binary, at the same path on every node
                      (default: ltm on PATH)
  --bake "OPTS"       Extra `ltm bake` options, split on whitespace
                      (e.g. "--size 64x64 --face-res 8")
  --compress "OPTS"   Extra `ltm compress` coding options, split on whitespace
                      (e.g. "--max-error 0.02 --entropy zstd")
  --sbatch "OPTS"     Extra sbatch options for every job, split on whitespace
                      (e.g. "--partition=batch --time=2:00:00 --cpus-per-task=8")
  --max-codings K     Fail when coding K still misses the error target (default 8)
  -h, --help          This help

The SCENE file and its meshes must be on shared storage too. Running the
same command again in the same DIR resumes: every array task whose output
exists skips its work (bake parts left unfinished resume inside ltm). A
DIR holding a pipeline of other settings is refused.
EOF
}

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
work="" shards=4 ltm="ltm" bake="" compress="" sbatch_opts="" max_codings=8 scene=""
while [ $# -gt 0 ]; do
    case "$1" in
        -h | --help) usage; exit 0 ;;
        --work) work="${2:?--work needs a directory}"; shift 2 ;;
        --shards) shards="${2:?--shards needs a number}"; shift 2 ;;
        --ltm) ltm="${2:?--ltm needs a path}"; shift 2 ;;
        --bake) bake="${2?--bake needs options}"; shift 2 ;;
        --compress) compress="${2?--compress needs options}"; shift 2 ;;
        --sbatch) sbatch_opts="${2?--sbatch needs options}"; shift 2 ;;
        --max-codings) max_codings="${2:?--max-codings needs a number}"; shift 2 ;;
        -*) echo "pipeline.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
        *)
            [ -z "$scene" ] || { echo "pipeline.sh: one SCENE only (see --help)" >&2; exit 2; }
            scene="$1"; shift ;;
    esac
done
fail() { echo "pipeline.sh: $*" >&2; exit 2; }
[ -n "$scene" ] || fail "no SCENE given (see --help)"
[ -n "$work" ] || fail "no --work DIR given (see --help)"
[ -f "$scene" ] || fail "scene $scene: no such file"
[[ "$shards" =~ ^[1-9][0-9]*$ ]] || fail "--shards $shards: expected a whole number >= 1"
[[ "$max_codings" =~ ^[1-9][0-9]*$ ]] || fail "--max-codings $max_codings: expected a whole number >= 1"
command -v sbatch >/dev/null 2>&1 || fail "sbatch not found: run on a Slurm submit host"
if [[ "$ltm" != */* ]]; then
    ltm="$(command -v "$ltm")" || fail "ltm not found on PATH: give --ltm PATH"
fi
[ -x "$ltm" ] || fail "--ltm $ltm: not an executable file"

mkdir -p "$work"
work="$(cd "$work" && pwd)"
ltm="$(cd "$(dirname "$ltm")" && pwd)/$(basename "$ltm")"
scene="$(cd "$(dirname "$scene")" && pwd)/$(basename "$scene")"

read -r -a bake_opts <<<"$bake"
read -r -a compress_opts <<<"$compress"
read -r -a sbatch_array <<<"$sbatch_opts"
env_text="$(
    declare -p ltm scene shards max_codings bake_opts compress_opts sbatch_array |
        sed -e 's/^declare -[a-z-]* ltm=/LTM=/' \
            -e 's/^declare -[a-z-]* scene=/SCENE=/' \
            -e 's/^declare -[a-z-]* shards=/SHARDS=/' \
            -e 's/^declare -[a-z-]* max_codings=/MAX_CODINGS=/' \
            -e 's/^declare -a bake_opts=/BAKE_OPTS=/' \
            -e 's/^declare -a compress_opts=/COMPRESS_OPTS=/' \
            -e 's/^declare -a sbatch_array=/SBATCH_OPTS=/'
)"
if [ -e "$work/pipeline.env" ] && [ "$(cat "$work/pipeline.env")" != "$env_text" ]; then
    fail "$work holds a pipeline of other settings ($work/pipeline.env); use another --work directory"
fi
printf '%s\n' "$env_text" >"$work/pipeline.env"
cp "$here/stage.sh" "$work/stage.sh"
chmod +x "$work/stage.sh"
echo "# submitted $(date -u +%Y-%m-%dT%H:%M:%SZ)" >>"$work/jobs"

"$work/stage.sh" "$work" start
echo "wait for the end with: $here/wait.sh $work"
