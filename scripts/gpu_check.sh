#!/usr/bin/env bash
# The GPU check anyone can run: on a machine with a GPU, without building, in under 5 minutes.
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
#   2. output frames: `bench frames` (biker and demo 1 M at 1080p, a frame a pass and four);
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
# then prints one table (python3, standard library only). Exit status 1 when parity fails.
# GPU_CHECK_QUICK=1 shrinks every workload (a smoke test of the script, e.g. on lavapipe):
# the figures then mean nothing.
set -euo pipefail

bin="${1:?usage: scripts/gpu_check.sh BINARY [DATA_DIR] [OUT_DIR]}"
repo="$(cd "$(dirname "$0")/.." && pwd)"
data="${2:-${SPLATRAJ_DATA:-$repo/../shared/data}}"
out="${3:-$(mktemp -d)}"
mkdir -p "$out"
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
compile_s=()
for attempt in first again; do
  echo "== wgpu: one guitar step in a fresh process ($attempt)" >&2
  started=$(date +%s.%N)
  "$bin" bench step --config configs/first-try/guitar.toml --steps 1 --set 'backend="wgpu"' \
    --set "scene.path=\"$data/guitar.compressed.ply\"" --json >/dev/null
  compile_s+=("$(python3 -c "print(f'{$(date +%s.%N) - $started:.1f}')")")
done
echo "{\"first_s\": ${compile_s[0]}, \"again_s\": ${compile_s[1]}}" >"$out/process_start.json"
for backend in wgpu flex; do
  echo "== $backend: bench launches" >&2
  "$bin" bench launches --backend "$backend" --iterations "$launch_iterations" --json \
    >"$out/launches_$backend.json"
done
for backend in wgpu flex; do
  echo "== $backend: bench render" >&2
  "$bin" bench render --backend "$backend" --sizes "$sizes" --resolutions 128 \
    --rasterizer fused --repeats "$repeats" --scene "$data/biker.compressed.ply" --json \
    >"$out/render_$backend.json"
  echo "== $backend: bench frames" >&2
  "$bin" bench frames --backend "$backend" --sizes "$frame_size" --frames 4 \
    --gaussians "$demo" --schedule pipelined,pipelined:4 --scene "$data/biker.compressed.ply" --json \
    >"$out/frames_$backend.json"
  echo "== $backend: bench step (guitar)" >&2
  "$bin" bench step --config configs/first-try/guitar.toml --steps "$steps" \
    --set "backend=\"$backend\"" --set "scene.path=\"$data/guitar.compressed.ply\"" --json \
    >"$out/step_$backend.json"
  echo "== $backend: first-try guitar" >&2
  "$bin" bench first-try configs/first-try/guitar.toml --set "backend=\"$backend\"" \
    --set "scene.path=\"$data/guitar.compressed.ply\"" "${quick[@]}" \
    --runs-dir "$out/runs_$backend" --json >"$out/first_try_$backend.json"
done
echo "== wgpu: bench render, each kernel waited for" >&2
CUBECL_DEBUG_OPTION=profile-medium "$bin" bench render --backend wgpu --sizes "$sizes" \
  --resolutions 128 --rasterizer fused --repeats 1 --scene "$data/biker.compressed.ply" --json \
  >"$out/render_wgpu_profiled.json"
echo "== wgpu: bench render, the backward summing one entry at a time" >&2
SPLATRAJ_ENTRY_SUMS=one-at-a-time "$bin" bench render --backend wgpu --sizes "$sizes" \
  --resolutions 128 --rasterizer fused --repeats "$repeats" --scene "$data/biker.compressed.ply" \
  --json >"$out/render_wgpu_one_at_a_time.json"
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

python3 - "$out" "$SECONDS" <<'PY'
import json, math, os, platform, subprocess, sys
out = sys.argv[1]
load = lambda name: json.load(open(os.path.join(out, name)))
try:
    gpu = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                         capture_output=True, text=True).stdout.strip() or "?"
except OSError:
    gpu = "?"
print(f"machine: {gpu}, {os.cpu_count()} CPU cores, {platform.platform()}")
start = load("process_start.json")
print(f"\na fresh process, four guitar steps (two step variants, one untimed step and one timed "
      f"each, kernels compiled on the way): {start['first_s']} s the first time, {start['again_s']} s again")
launches = {b: load(f"launches_{b}.json") for b in ("wgpu", "flex")}
print("\n| µs each (a launch of the chain, a read, an upload) | wgpu | wgpu GB/s | wgpu launches an iteration | wgpu queued, µs an iteration | flex | flex GB/s |")
print("|---|---:|---:|---:|---:|---:|---:|")
rate = lambda r: f"{r['gb_per_s']:.2f}" if r.get("gb_per_s") else "-"
for w, f in zip(launches["wgpu"], launches["flex"]):
    print(f"| {w['probe']} | {w['us_each']:.1f} | {rate(w)} | {w['launches'] / w['iterations']:.1f} | "
          f"{w['queued_us']:.1f} | {f['us_each']:.1f} | {rate(f)} |")
render = {b: load(f"render_{b}.json") for b in ("wgpu", "flex")}
key = lambda r: (r["scene"], r["gaussians"], r["resolution"], r["pruning"])
flex_rows = {key(r): r for r in render["flex"]["rows"] if not r.get("skipped")}
failed = []
def grad_diff(r, f):
    """|dΦ wgpu − dΦ flex| / |dΦ flex| of one mask pass."""
    g, h = r.get("grad_pose", []), f.get("grad_pose", [])
    norm = math.sqrt(sum(x * x for x in h)) or 1.0
    return math.sqrt(sum((a - b) ** 2 for a, b in zip(g, h))) / norm if g and h else float("nan")
print("\n| mask pass, fwd+bwd | wgpu ms | flex ms | wgpu/flex | launches | reads | KB up | TCE wgpu / flex | |dΦ| diff / |dΦ| |")
print("|---|---:|---:|---:|---:|---:|---:|---|---:|")
for r in render["wgpu"]["rows"]:
    f = flex_rows.get(key(r))
    if r.get("skipped") or f is None:
        continue
    diff = grad_diff(r, f)
    tce_ok = abs(r["tce"] - f["tce"]) <= 1e-3 or (math.isnan(r["tce"]) and math.isnan(f["tce"]))
    if not (tce_ok and diff <= 1e-3 and abs(r["coverage"] - f["coverage"]) <= 1e-3):
        failed.append(f"{key(r)}: TCE {r['tce']} vs {f['tce']}, gradient {diff:.2e}")
    c = r.get("counts", {})
    print(f"| {r['scene']} {r['gaussians']} {r['resolution']}² {r['pruning']} | {r['forward_backward_ms']:.2f} | "
          f"{f['forward_backward_ms']:.2f} | {r['forward_backward_ms'] / f['forward_backward_ms']:.2f} | "
          f"{c.get('launches', '-')} | {c.get('reads', '-')} | {c.get('bytes_up', 0) / 1024:.1f} | "
          f"{r['tce']:.6f} / {f['tce']:.6f} | {diff:.1e} |")
def variant_table(title, default, variant, name):
    """The wgpu mask passes against the same passes run another way (`name`), and its parity."""
    other = {key(r): r for r in load(name)["rows"] if not r.get("skipped")}
    print(f"\n| {title}, fwd+bwd ms | {default} | {variant} | |dΦ| diff / |dΦ|, {variant} |")
    print("|---|---:|---:|---:|")
    for r in render["wgpu"]["rows"]:
        o, f = other.get(key(r)), flex_rows.get(key(r))
        if r.get("skipped") or o is None or f is None:
            continue
        diff = grad_diff(o, f)
        if not diff <= 1e-3:
            failed.append(f"{key(r)} {variant}: gradient {diff:.2e}")
        print(f"| {r['scene']} {r['gaussians']} {r['resolution']}² {r['pruning']} | "
              f"{r['forward_backward_ms']:.2f} | {o['forward_backward_ms']:.2f} | {diff:.1e} |")
variant_table("backward's entry sums", "pipelined", "one at a time", "render_wgpu_one_at_a_time.json")
variant_table("tile lists in the backward", "cut", "whole", "render_wgpu_whole_lists.json")
profiled = load("render_wgpu_profiled.json")
names = [n for n, _ in profiled["rows"][0]["stages_ms"]] if profiled["rows"] else []
print("\n| wgpu stages, ms, each kernel waited for | " + " | ".join(names) + " |")
print("|---|" + "---:|" * len(names))
for r in profiled["rows"]:
    if not r.get("skipped"):
        stages = dict(r["stages_ms"])
        print(f"| {r['scene']} {r['gaussians']} {r['resolution']}² {r['pruning']} | "
              + " | ".join(f"{stages.get(n, 0):.2f}" for n in names) + " |")
frames = {b: load(f"frames_{b}.json") for b in ("wgpu", "flex")}
print("\n| 1080p output frame | wgpu ms | flex ms |")
print("|---|---:|---:|")
for r in frames["wgpu"]["rows"]:
    f = next((x for x in frames["flex"]["rows"] if (x["scene"], x["gaussians"], x["width"], x["schedule"]) ==
              (r["scene"], r["gaussians"], r["width"], r["schedule"])), None)
    if f:
        print(f"| {r['scene']} {r['gaussians']} {r['schedule']} | {r['frame_ms']:.0f} | {f['frame_ms']:.0f} |")
steps = {b: load(f"step_{b}.json") for b in ("wgpu", "flex")}
print("\n| optimisation step, guitar | ms | launches | reads | render calls | compositing workgroups | best loss |")
print("|---|---:|---:|---:|---:|---:|---:|")
def step_row(label, r):
    c = r["counts"]
    print(f"| {label}, {r['passes']} | {r['ms_per_step']:.1f} | {c['launches']} | {c['reads']} | "
          f"{c.get('renders', '-')} | {c.get('segments', '-')} | {r['best_total']:.6f} |")
for b in ("wgpu", "flex"):
    for r in steps[b]:
        step_row(f"{b}" + (", lists cut at 1024" if b == "wgpu" else ""), r)
for r in load("step_wgpu_whole_lists.json"):
    step_row("wgpu, lists whole", r)
for entries in (256, 512, 2048):
    for r in load(f"step_wgpu_segments_{entries}.json"):
        step_row(f"wgpu, lists cut at {entries}", r)
profiled_steps = load("step_wgpu_profiled.json")
names = [n for n, _ in profiled_steps[0]["stages_ms"]] if profiled_steps else []
print("\n| wgpu step, ms, each kernel waited for | " + " | ".join(names) + " | ms a step |")
print("|---|" + "---:|" * (len(names) + 1))
for r in profiled_steps:
    stages = dict(r["stages_ms"])
    print(f"| guitar, {r['passes']} | " + " | ".join(f"{stages.get(n, 0):.2f}" for n in names)
          + f" | {r['ms_per_step']:.2f} |")
runs = {b: load(f"first_try_{b}.json") for b in ("wgpu", "flex")}
print("\n| first-try guitar | wgpu | flex |")
print("|---|---:|---:|")
w, f = runs["wgpu"][0], runs["flex"][0]
print(f"| whole run, s | {w['total_s']:.1f} | {f['total_s']:.1f} |")
print(f"| optimisation, s | {w['optimisation_s']:.1f} | {f['optimisation_s']:.1f} |")
print(f"| metrics, s | {w['metrics_s']:.1f} | {f['metrics_s']:.1f} |")
print(f"| frames, video and exports, s | {w['frames_s']:.1f} | {f['frames_s']:.1f} |")
for stage in ("preparation", "optimisation", "metrics", "frames"):
    c = (w.get("counts") or {}).get(stage)
    if c:
        print(f"| {stage} on wgpu: launches, reads, MB down, MB up | {c['launches']}, {c['reads']}, "
              f"{c['bytes_down'] / 2**20:.1f}, {c['bytes_up'] / 2**20:.1f} | |")
for a, b in zip(w["windows"], f["windows"]):
    ta, tb = a.get("tce_middle"), b.get("tce_middle")
    print(f"| {a['name']}: verdict, TCE | {'pass' if a['pass'] else 'FAIL'}, {ta} | {'pass' if b['pass'] else 'FAIL'}, {tb} |")
    if a["pass"] != b["pass"]:
        failed.append(f"guitar {a['name']}: verdicts differ")
print(f"\nspeed-up of the whole run: {f['total_s'] / w['total_s']:.2f}x (JSON in {out})")
print(f"the check's measurements took {int(sys.argv[2]) / 60:.1f} minutes")
if failed:
    print("PARITY FAILED:\n  " + "\n  ".join(failed))
    sys.exit(1)
print("parity: wgpu matches flex on every mask pass and every verdict")
PY
