#!/usr/bin/env bash
# The GPU check anyone can run on a machine with a GPU, without building; it prints its length.
#
#   scripts/gpu_check.sh BINARY [DATA_DIR] [OUT_DIR]
#
# BINARY   a splatraj built with `cargo build --release --features wgpu` (flex is in it too)
# DATA_DIR the folder holding biker.compressed.ply and guitar.compressed.ply (default:
#          $SPLATRAJ_DATA, else ../shared/data beside the repository)
# OUT_DIR  where the JSON of every measurement goes (default: a fresh temporary folder)
#
# Runs, on wgpu and on flex (the same machine's CPU cores):
#   1. parity and the mask pass: `bench render` (demo 100k and 1 M, 128², pruned and full; biker
#      128² full): image (TCE, TRE, coverage) and pose gradient, wgpu against flex, and the
#      forward + backward time, kernel launches, reads and bytes per pass;
#   2. output frames: `bench frames` (biker and demo 1 M at 1080p, a frame a pass and four;
#      both at SH degree 3, as real captures hold it: zero coefficients added);
#   3. the first-try guitar run (`configs/first-try/guitar.toml`) whole: time, each window's
#      verdict and TCE;
#   4. an optimisation step of the guitar config: `bench step` with its windows in one render
#      call and in a call per window: ms per step, launches, reads and render calls a step;
#   5. where a wgpu pass spends its time: the mask passes of 1. again with CubeCL's profiling
#      on (`CUBECL_DEBUG_OPTION=profile-medium` waits for each kernel), so that each stage's
#      column holds its kernels' time instead of "other" holding all of it (a GPU runs
#      asynchronously: without it only the final read waits);
#   6. the compositing backward's two ways of summing a list entry over a tile (pipelined, the
#      default, against one entry at a time: SPLATRAJ_ENTRY_SUMS): the mask passes of 1. on
#      wgpu both ways, time and parity;
#   6b. the compositing kernels launched unchecked (SPLATRAJ_INDEX_CHECKS=trusted: no guard
#      on each index into a buffer, no bounded loops) against the default: the mask passes
#      of 1. on wgpu both ways, time and parity;
#   7. where a wgpu optimisation step spends its time: `bench step` on the guitar config with
#      each kernel waited for, by render stage, beside the time a step (the stages'
#      totals also hold the run's closing evaluation, so read them as shares, not a sum);
#   8. the compositing backward with long tile lists cut into segments replayed in parallel
#      (the default) against whole lists, one workgroup each (SPLATRAJ_SEGMENT_ENTRIES=0):
#      the mask passes of 1. and the guitar step of 4. on wgpu both ways, time and parity,
#      and the guitar step with segments of 256, 512 and 2048 entries (the step table's
#      "compositing workgroups" is the forwards' work tiles or segments a step);
#   9. what a launch, a read back and an upload cost on each backend, apart from arithmetic,
#      and the bandwidth each way for 16 MiB (`bench launches`): the floor of a step's ~120
#      launches and one read, and what uploading host-made tile lists costs, which decide
#      whether fewer launches, less host work or binning on the device is the next lever
#      (docs/gpu.md);
#   0. first of all, what compiling a run's ~300 kernels costs a process: one guitar step on
#      wgpu in a fresh process, twice (the first on this machine may also fill the driver's
#      shader cache; the second pays only what every process pays).
# then prints one table (scripts/gpu_check_table.py, python3's standard library only; it also
# tabulates a partial OUT_DIR: `python3 scripts/gpu_check_table.py OUT_DIR`). Exit status 1
# when parity fails. The cheap, decisive measurements come first (9., then 0.).
# GPU_CHECK_QUICK=1 shrinks every workload (a smoke test of the script, e.g. on lavapipe):
# the figures then mean nothing. GPU_CHECK_SHORT=1 measures a second build beside the first
# in a minute or two (`.gpu/run.sh` does it for a SPIR-V build, docs/gpu.md): 9., the 100k
# mask passes of 1. with their parity, on wgpu only the guitar step of 4. and the profiled
# step of 7., then 0.
set -euo pipefail

bin="${1:?usage: scripts/gpu_check.sh BINARY [DATA_DIR] [OUT_DIR]}"
repo="$(cd "$(dirname "$0")/.." && pwd)"
data="${2:-${SPLATRAJ_DATA:-$repo/../shared/data}}"
out="${3:-$(mktemp -d)}"
mkdir -p "$out"
# The first-try runs' folders (frames, video) stay out of OUT_DIR, which holds only JSON: on a
# borrowed machine OUT_DIR comes back, also when a time limit stops the check.
runs="$(mktemp -d)"
bin="$(cd "$(dirname "$bin")" && pwd)/$(basename "$bin")"
for f in biker.compressed.ply guitar.compressed.ply; do
  [ -f "$data/$f" ] || { echo "gpu_check: $data/$f is missing (give DATA_DIR)" >&2; exit 2; }
done
# Absolute: a config resolves a relative `scene.path` against its own folder.
data="$(cd "$data" && pwd)"
# Mesa and the loader complain without it; kernels compile once per machine.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
export CUBECL_AUTOTUNE_LEVEL="${CUBECL_AUTOTUNE_LEVEL:-minimal}"
cd "$repo"

sizes=100000,1000000 repeats=5 frame_size=1080p demo=1000000 steps=10 launch_iterations=2000 quick=()
if [ "${GPU_CHECK_QUICK:-0}" = 1 ]; then
  sizes=10000 repeats=1 frame_size=160x90 demo=10000 steps=2 launch_iterations=50
  quick=(--set optimiser.iterations=3 --set output.frames=3 --set output.width=160
    --set output.height=90 --set output.metric_samples=8)
fi
if [ "${GPU_CHECK_SHORT:-0}" = 1 ] && [ "${GPU_CHECK_QUICK:-0}" != 1 ]; then
  sizes=100000
fi
for backend in wgpu flex; do
  echo "== $backend: bench launches" >&2
  "$bin" bench launches --backend "$backend" --iterations "$launch_iterations" --json \
    >"$out/launches_$backend.json"
done
fresh_process_twice() {
  local compile_s=() attempt started
  for attempt in first again; do
    echo "== wgpu: one guitar step in a fresh process ($attempt)" >&2
    started=$(date +%s.%N)
    "$bin" bench step --config configs/first-try/guitar.toml --steps 1 --set 'backend="wgpu"' \
      --set "scene.path=\"$data/guitar.compressed.ply\"" --json >/dev/null
    compile_s+=("$(python3 -c "print(f'{$(date +%s.%N) - $started:.1f}')")")
  done
  echo "{\"first_s\": ${compile_s[0]}, \"again_s\": ${compile_s[1]}}" >"$out/process_start.json"
}
# The short check measures the passes and the step first: they decide between two builds.
[ "${GPU_CHECK_SHORT:-0}" = 1 ] || fresh_process_twice
for backend in wgpu flex; do
  echo "== $backend: bench render" >&2
  "$bin" bench render --backend "$backend" --sizes "$sizes" --resolutions 128 \
    --rasterizer fused --repeats "$repeats" --scene "$data/biker.compressed.ply" --json \
    >"$out/render_$backend.json"
  if [ "${GPU_CHECK_SHORT:-0}" = 1 ]; then
    [ "$backend" = wgpu ] || continue
    echo "== $backend: bench step (guitar)" >&2
    "$bin" bench step --config configs/first-try/guitar.toml --steps "$steps" \
      --set "backend=\"$backend\"" --set "scene.path=\"$data/guitar.compressed.ply\"" --json \
      >"$out/step_$backend.json"
    continue
  fi
  echo "== $backend: bench frames" >&2
  "$bin" bench frames --backend "$backend" --sizes "$frame_size" --frames 4 --sh-degree 3 \
    --gaussians "$demo" --schedule pipelined,pipelined:4 --scene "$data/biker.compressed.ply" --json \
    >"$out/frames_$backend.json"
  echo "== $backend: bench step (guitar)" >&2
  "$bin" bench step --config configs/first-try/guitar.toml --steps "$steps" \
    --set "backend=\"$backend\"" --set "scene.path=\"$data/guitar.compressed.ply\"" --json \
    >"$out/step_$backend.json"
  echo "== $backend: first-try guitar" >&2
  "$bin" bench first-try configs/first-try/guitar.toml --set "backend=\"$backend\"" \
    --set "scene.path=\"$data/guitar.compressed.ply\"" "${quick[@]}" \
    --runs-dir "$runs/$backend" --json >"$out/first_try_$backend.json"
done
if [ "${GPU_CHECK_SHORT:-0}" = 1 ]; then
  echo "== wgpu: bench step (guitar), each kernel waited for" >&2
  CUBECL_DEBUG_OPTION=profile-medium "$bin" bench step --config configs/first-try/guitar.toml \
    --steps "$steps" --set 'backend="wgpu"' --set "scene.path=\"$data/guitar.compressed.ply\"" \
    --json >"$out/step_wgpu_profiled.json"
  fresh_process_twice
  python3 "$repo/scripts/gpu_check_table.py" "$out" "$SECONDS"
  exit 0
fi
echo "== wgpu: bench render, each kernel waited for" >&2
CUBECL_DEBUG_OPTION=profile-medium "$bin" bench render --backend wgpu --sizes "$sizes" \
  --resolutions 128 --rasterizer fused --repeats 1 --scene "$data/biker.compressed.ply" --json \
  >"$out/render_wgpu_profiled.json"
echo "== wgpu: bench render, the backward summing one entry at a time" >&2
SPLATRAJ_ENTRY_SUMS=one-at-a-time "$bin" bench render --backend wgpu --sizes "$sizes" \
  --resolutions 128 --rasterizer fused --repeats "$repeats" --scene "$data/biker.compressed.ply" \
  --json >"$out/render_wgpu_one_at_a_time.json"
echo "== wgpu: bench render, the compositing kernels launched unchecked" >&2
SPLATRAJ_INDEX_CHECKS=trusted "$bin" bench render --backend wgpu --sizes "$sizes" \
  --resolutions 128 --rasterizer fused --repeats "$repeats" --scene "$data/biker.compressed.ply" \
  --json >"$out/render_wgpu_unchecked.json"
echo "== wgpu: bench render and bench step, lists whole" >&2
SPLATRAJ_SEGMENT_ENTRIES=0 "$bin" bench render --backend wgpu --sizes "$sizes" \
  --resolutions 128 --rasterizer fused --repeats "$repeats" --scene "$data/biker.compressed.ply" \
  --json >"$out/render_wgpu_whole_lists.json"
SPLATRAJ_SEGMENT_ENTRIES=0 "$bin" bench step --config configs/first-try/guitar.toml \
  --steps "$steps" --set 'backend="wgpu"' --set "scene.path=\"$data/guitar.compressed.ply\"" --json \
  >"$out/step_wgpu_whole_lists.json"
echo "== wgpu: bench step, lists cut at other lengths" >&2
for entries in 256 512 2048; do
  SPLATRAJ_SEGMENT_ENTRIES=$entries "$bin" bench step --config configs/first-try/guitar.toml \
    --steps "$steps" --set 'backend="wgpu"' --set "scene.path=\"$data/guitar.compressed.ply\"" --json \
    >"$out/step_wgpu_segments_$entries.json"
done
echo "== wgpu: bench step (guitar), each kernel waited for" >&2
CUBECL_DEBUG_OPTION=profile-medium "$bin" bench step --config configs/first-try/guitar.toml \
  --steps "$steps" --set 'backend="wgpu"' --set "scene.path=\"$data/guitar.compressed.ply\"" --json \
  >"$out/step_wgpu_profiled.json"

python3 "$repo/scripts/gpu_check_table.py" "$out" "$SECONDS"
