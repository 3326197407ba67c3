#!/bin/bash
# Checks the Slurm recipe of docs/study.md ("On a cluster: shards and Slurm") as written.
#
# What it checks: the two ```sh blocks of that section (study.sbatch, submit.sh) are taken
# verbatim from the docs into a scratch folder and submit.sh is run there. By default `sbatch` is
# a stand-in that does what real Slurm does with these files at submission and launch: it fails a
# job whose --output folder does not exist (Slurm opens the log before the task starts and makes
# no folders, so every array task ended in JobLaunchFailure), and it records each submission;
# `sinfo` is a stand-in for one small node (2 CPUs, 2000 MB) and `splatraj` one on PATH.
# The check then asserts that every job's log folder existed when it was submitted, that the
# merge depends on the array (afterok) with --kill-on-invalid-dep=yes (else it pends forever
# after a failed shard), that each shard's --shard is K/N with N the --array's size, that the
# shards' CPUs and memory fit the node (else Slurm leaves them PENDING without a word), that the
# merge asks for one CPU and little memory, and that the jobs run splatraj by absolute path.
#
# With REAL_SLURM=1 the real sbatch is used (a cluster or single-node slurmctld must answer, and
# `splatraj` and configs/demo.toml must exist in the scratch folder's parent): the script then
# only submits and prints the job ids and `squeue`/`sacct` afterwards.
#
# Run: scripts/check_study_recipe.sh [docs/study.md]     (exit status 0 when the recipe holds)
set -euo pipefail

docs=$(realpath "${1:-docs/study.md}")
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# The section's sh blocks, in order: study.sbatch, then submit.sh.
python3 - "$docs" "$work" <<'EOF'
import re, sys
text = open(sys.argv[1]).read()
section = text[text.index("## On a cluster"):]
blocks = re.findall(r"```sh\n(.*?)```", section, re.S)
names = {"study.sbatch": None, "submit.sh": None}
for b in blocks:
    for name in names:
        if f"# {name}:" in b:
            names[name] = b
missing = [n for n, b in names.items() if b is None]
if missing:
    sys.exit(f"docs: no sh block headed '# {missing[0]}:' in the cluster section")
for name, b in names.items():
    open(f"{sys.argv[2]}/{name}", "w").write(b)
EOF
bash -n "$work/study.sbatch"
bash -n "$work/submit.sh"

if [[ "${REAL_SLURM:-0}" == 1 ]]; then
    (cd "$work" && bash submit.sh)
    sleep 5
    squeue || true
    sacct -X --format=JobID,JobName,State,ExitCode || true
    exit 0
fi

# Stand-in sbatch: writes one line per job to $work/jobs.log and fails like Slurm when a log
# folder is missing.
mkdir -p "$work/bin"
cat > "$work/bin/sbatch" <<'EOF'
#!/bin/bash
set -euo pipefail
output="slurm-%j.out"; array=""; dep=""; kill=no; script=""; cpus=""; mem=""; export_=""
for a in "$@"; do
    case "$a" in
        --output=*) output=${a#--output=} ;;
        --cpus-per-task=*) cpus=${a#--cpus-per-task=} ;;
        --mem=*) mem=${a#--mem=} ;;
        --export=*) export_=${a#--export=} ;;
        --array=*) array=${a#--array=} ;;
        --dependency=*) dep=${a#--dependency=} ;;
        --kill-on-invalid-dep=*) kill=${a#--kill-on-invalid-dep=} ;;
        --*) ;;
        *) [[ -z "$script" && -f "$a" ]] && script=$a ;;
    esac
done
if [[ -n "$script" ]]; then
    # #SBATCH lines count unless given on the command line.
    while read -r key value; do
        case "$key" in
            --output) [[ "$output" == "slurm-%j.out" ]] && output=$value ;;
            --array) [[ -z "$array" ]] && array=$value ;;
            --cpus-per-task) [[ -z "$cpus" ]] && cpus=$value ;;
            --mem) [[ -z "$mem" ]] && mem=$value ;;
        esac
    done < <(sed -n 's/^#SBATCH \(--[a-z-]*\)=\(.*\)$/\1 \2/p' "$script")
fi
id=$(( $(wc -l < "$JOBS") + 100 ))
if [[ ! -d "$(dirname "$output")" ]]; then
    echo "stand-in sbatch: job $id: log folder $(dirname "$output") missing: JobLaunchFailure" >&2
    exit 1
fi
echo "$id|$array|$dep|$kill|$script|$cpus|$mem|$export_" >> "$JOBS"
echo "$id"
EOF
chmod +x "$work/bin/sbatch"
# Stand-in sinfo: one node of 2 CPUs and 2000 MB (the single-node cluster of issue 39).
cat > "$work/bin/sinfo" <<'EOF'
#!/bin/bash
echo "2 2000"
EOF
# Stand-in splatraj: submit.sh only looks it up.
printf '#!/bin/bash\nexit 0\n' > "$work/bin/splatraj"
chmod +x "$work/bin/sinfo" "$work/bin/splatraj"

export JOBS="$work/jobs.log"
: > "$JOBS"
(cd "$work" && PATH="$work/bin:$PATH" bash submit.sh > /dev/null)

fail() { echo "check_study_recipe: $*" >&2; exit 1; }
[[ $(wc -l < "$JOBS") == 2 ]] || fail "expected 2 submissions (array, merge), got $(wc -l < "$JOBS")"
IFS='|' read -r array_id range _ _ script shard_cpus shard_mem shard_export < <(sed -n 1p "$JOBS")
IFS='|' read -r _ _ dep kill _ merge_cpus merge_mem _ < <(sed -n 2p "$JOBS")
[[ "$script" == study.sbatch ]] || fail "the first job is not study.sbatch"
[[ "$dep" == "afterok:$array_id" ]] || fail "the merge depends on '$dep', not afterok:$array_id"
[[ "$kill" == yes ]] || fail "the merge has no --kill-on-invalid-dep=yes"
megabytes() { case "$1" in *G) echo $(( ${1%G} * 1024 ));; *M) echo "${1%M}";; *) echo "$1";; esac; }
[[ -n "$shard_cpus" && "$shard_cpus" -le 2 ]] || fail "a shard asks for '$shard_cpus' CPUs on a 2-CPU node"
[[ -n "$shard_mem" && $(megabytes "$shard_mem") -le 2000 ]] \
    || fail "a shard asks for '$shard_mem' of memory on a 2000 MB node"
[[ "$merge_cpus" == 1 && -n "$merge_mem" && $(megabytes "$merge_mem") -le 2048 ]] \
    || fail "the merge asks for '$merge_cpus' CPUs and '$merge_mem' (one CPU and little memory expected)"
[[ "$shard_export" == *"SPLATRAJ=$work/bin/splatraj"* ]] \
    || fail "the shards are not told splatraj's absolute path (--export: '$shard_export')"
# --array=1-N and --shard K/N agree (N written out, so a resubmitted shard keeps it).
n=${range#1-}
grep -q -- "--shard \"\${SLURM_ARRAY_TASK_ID}/$n\"" "$work/study.sbatch" \
    || fail "study.sbatch's --shard does not end in /$n (its --array is $range)"
echo "check_study_recipe: the recipe in $docs submits (array $range, merge afterok + kill-on-invalid-dep, log folders made)"
