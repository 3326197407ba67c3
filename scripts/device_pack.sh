#!/usr/bin/env bash
# Packs what a borrowed GPU machine needs to run scripts/gpu_check.sh without building, so that a
# session lent one spends its device minutes measuring: the wgpu binary (stripped, xz), the two
# scenes the check reads, the Vulkan loader's Debian packages, and the script the machine runs.
#
#   cargo build --release --features wgpu          # here, about 30 minutes on 2 cores
#   scripts/device_pack.sh [BINARY] [DATA_DIR] [BRANCH_BINARY] [SPIRV_BINARY]
#                                                  # here: fills .gpu/ (git ignores it)
#
# then, on the machine (the workplace's device tool: `run` with carry [".gpu"]):
#
#   bash .gpu/run.sh                               # GPU_CHECK_QUICK=1 for a smoke test
#
# It first asks the binary what wgpu runs on and stops (status 3, with the Vulkan ICDs it saw)
# unless that is a GPU: a smoke test on a machine without one adds GPU_CHECK_ALLOW_EMULATED=1.
#
# which writes $OUT/gpu_check.txt (the table and the log) and $OUT/gpu_check_json/ (every
# measurement's JSON, written as it finishes). The check stops after GPU_CHECK_SECONDS (500)
# and then tabulates what it measured; `python3 scripts/gpu_check_table.py DIR` does the same
# here on the JSON that came back. BRANCH_BINARY (optional) is a wgpu build of a branch to
# compare, such as gpu-forward-cut: after the check, the machine times one profiled guitar step
# with it (GPU_CHECK_BRANCH_SECONDS, 80) and prints that step's stage table below the check's,
# to read beside the check's own "wgpu step, ms, each kernel waited for". SPIRV_BINARY
# (optional; BRANCH_BINARY may then be "") is a `--features vulkan` build: before the check,
# the machine runs the short check with it (GPU_CHECK_SHORT=1, GPU_CHECK_SPIRV_SECONDS, 120):
# CubeCL's SPIR-V compiler beside WGSL on the same GPU. BINARY defaults to
# $CARGO_TARGET_DIR/release/splatraj (else target/release/splatraj), DATA_DIR to
# ../shared/data. Everything travels within the tool's 64 MiB. The loader packages follow the
# device notes of this workplace (Debian's libvulkan1, unpacked over / on the machine; the
# NVIDIA ICD is the machine's own).
set -euo pipefail
cd "$(dirname "$0")/.."

bin="${1:-${CARGO_TARGET_DIR:-target}/release/splatraj}"
data="${2:-../shared/data}"
branch_bin="${3:-}"
spirv_bin="${4:-}"
[ -x "$bin" ] || { echo "device_pack: no binary at $bin (build with --features wgpu)" >&2; exit 2; }
for extra in "$branch_bin" "$spirv_bin"; do
  if [ -n "$extra" ] && [ ! -x "$extra" ]; then
    echo "device_pack: no binary at $extra" >&2
    exit 2
  fi
done
for f in biker.compressed.ply guitar.compressed.ply; do
  [ -f "$data/$f" ] || { echo "device_pack: $data/$f is missing (give DATA_DIR)" >&2; exit 2; }
done
grep -qx '/.gpu/' .git/info/exclude 2>/dev/null || echo '/.gpu/' >>.git/info/exclude

rm -rf .gpu && mkdir -p .gpu/data .gpu/deb
cp "$data/biker.compressed.ply" "$data/guitar.compressed.ply" .gpu/data/
# Debug info is most of a release binary's 600 MB; the machine needs none of it.
pack_binary() { strip -o ".gpu/$2" "$1" && xz -T0 -6 ".gpu/$2"; }
pack_binary "$bin" splatraj
if [ -n "$branch_bin" ]; then
  pack_binary "$branch_bin" splatraj-branch
fi
if [ -n "$spirv_bin" ]; then
  pack_binary "$spirv_bin" splatraj-spirv
fi
# The loader for the machine's amd64 Debian, whatever this machine runs.
lists=/tmp/device_pack_apt
mkdir -p "$lists/partial"
apt_opts=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$lists")
apt-get "${apt_opts[@]}" update -qq
(cd .gpu/deb && apt-get "${apt_opts[@]}" download -qq libvulkan1)

cat >.gpu/run.sh <<'RUN'
#!/usr/bin/env bash
# Runs on the GPU machine, from the repository root: unpacks what device_pack.sh packed and runs
# scripts/gpu_check.sh, the table and log into $OUT/gpu_check.txt, the JSON into one archive.
set -uo pipefail
out="${OUT:?run on the device machine, where OUT is set}"
if ! ldconfig -p | grep -q libvulkan.so.1; then
  for f in .gpu/deb/*.deb; do dpkg -x "$f" /; done
  ldconfig
fi
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f "$icd" ] && export VK_DRIVER_FILES="${VK_DRIVER_FILES:-$icd}"
xz -dkf .gpu/splatraj.xz && chmod +x .gpu/splatraj
# What wgpu runs on, before any device minute goes to the check: without the GPU's Vulkan ICD
# wgpu falls back to Mesa's CPU emulation and the check would measure the CPU (and use up the
# session's device time). GPU_CHECK_ALLOW_EMULATED=1 runs it anyway, as a smoke test does.
export XDG_RUNTIME_DIR="${XDG_RUNTIME_DIR:-$(mktemp -d)}"
probe="$(.gpu/splatraj bench render --one demo:1000:64:object:fused --backend wgpu --repeats 1 \
  --json 2>"$out/probe.err" | tail -1)"
device="$(printf '%s' "$probe" | python3 -c 'import json, sys; print(json.load(sys.stdin)["device"])' \
  2>/dev/null)"
echo "wgpu runs on: ${device:-nothing (the probe failed)}" | tee "$out/gpu_check.txt"
# Every adapter wgpu sees, the one it took marked (a binary older than `devices` says so).
.gpu/splatraj devices 2>&1 | tee -a "$out/gpu_check.txt"
case "$device" in
  "GPU "*) ;;
  *)
    if [ "${GPU_CHECK_ALLOW_EMULATED:-0}" != 1 ]; then
      {
        echo "no GPU for wgpu: the check is not run (GPU_CHECK_ALLOW_EMULATED=1 runs it anyway)"
        tail -5 "$out/probe.err"
        ls /usr/share/vulkan/icd.d /etc/vulkan/icd.d /usr/local/nvidia/share/vulkan/icd.d 2>&1
        echo "VK_DRIVER_FILES=${VK_DRIVER_FILES:-}"
        vulkaninfo --summary 2>&1 | head -30
      } | tee -a "$out/gpu_check.txt"
      exit 3
    fi
    ;;
esac
# Every measurement's JSON straight under OUT: what finished comes back even when the device
# tool's time limit stops the check (give `run` a timeout_s above GPU_CHECK_SECONDS).
json="$out/gpu_check_json"
mkdir -p "$json"
# The device tool gives a command 600 s: the SPIR-V build's short check comes out of the
# main check's time.
check_seconds="${GPU_CHECK_SECONDS:-500}"
{
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true
  git log -1 --format='commit %h %s' 2>/dev/null || true
  if [ -f .gpu/splatraj-spirv.xz ]; then
    xz -dkf .gpu/splatraj-spirv.xz && chmod +x .gpu/splatraj-spirv
    spirv_seconds="${GPU_CHECK_SPIRV_SECONDS:-120}"
    check_seconds="${GPU_CHECK_SECONDS:-$((500 - spirv_seconds))}"
    echo "== the SPIR-V build (--features vulkan): the short check, WGSL's table follows"
    GPU_CHECK_SHORT=1 timeout "$spirv_seconds" scripts/gpu_check.sh .gpu/splatraj-spirv \
      .gpu/data "$out/gpu_check_json_spirv"
    spirv_status=$?
    if [ "$spirv_status" -ne 0 ]; then
      echo "the SPIR-V short check exited with status $spirv_status; what it measured:"
      python3 scripts/gpu_check_table.py "$out/gpu_check_json_spirv" || true
    fi
  fi
  timeout "$check_seconds" scripts/gpu_check.sh .gpu/splatraj .gpu/data "$json"
  status=$?
  echo "gpu_check exit status $status"
  if [ "$status" -eq 124 ]; then
    echo "gpu_check stopped after $check_seconds s; the table of what it measured:"
    python3 scripts/gpu_check_table.py "$json"
  fi
  if [ -f .gpu/splatraj-branch.xz ]; then
    xz -dkf .gpu/splatraj-branch.xz && chmod +x .gpu/splatraj-branch
    echo "== the branch's binary: bench step, 4 guitar steps, each kernel waited for"
    CUBECL_DEBUG_OPTION=profile-medium timeout "${GPU_CHECK_BRANCH_SECONDS:-80}" \
      .gpu/splatraj-branch bench step --config configs/first-try/guitar.toml --steps 4 \
      --set 'backend="wgpu"' --set "scene.path=\"$PWD/.gpu/data/guitar.compressed.ply\"" \
      || echo "the branch's step exited with status $?"
  fi
} >>"$out/gpu_check.txt" 2>&1
tail -60 "$out/gpu_check.txt"
grep -q '^gpu_check exit status 0$' "$out/gpu_check.txt"
RUN
chmod +x .gpu/run.sh
du -sh .gpu
# The device tool carries the tracked tree and .gpu together, 64 MiB in all: with the tree at
# ~23 MB, three binaries (~16 MB each) do not fit beside the scenes; pack two.
tree=$(git ls-files -z | xargs -0 du -cb 2>/dev/null | tail -1 | cut -f1)
packed=$(du -sb .gpu | cut -f1)
if [ $((tree + packed)) -gt $((64 << 20)) ]; then
  echo "device_pack: warning: the tree ($((tree >> 20)) MiB) and .gpu ($((packed >> 20)) MiB)" \
    "exceed the device tool's 64 MiB; leave out the branch or the SPIR-V binary" >&2
fi
echo "device_pack: .gpu/ is ready; on the machine: bash .gpu/run.sh (carry [\".gpu\"])"
