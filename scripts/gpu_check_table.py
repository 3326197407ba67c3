#!/usr/bin/env python3
"""The table of scripts/gpu_check.sh, from the JSON its measurements wrote (standard library only).

    python3 scripts/gpu_check_table.py OUT_DIR [SECONDS_TAKEN]

gpu_check.sh calls it at its end. It also reads a partial OUT_DIR: a check stopped by a time
limit on a borrowed GPU machine (its JSON written so far comes back) still gives every table
whose measurements finished, and says which did not. Exit status 1 when parity fails on what
was measured.
"""
import json
import math
import os
import platform
import subprocess
import sys

out = sys.argv[1]
failed = []
missing = []
# Parity comparisons made (mask passes and verdicts measured on both backends).
compared = []


def load(name):
    with open(os.path.join(out, name)) as f:
        return json.load(f)


def section(title, show):
    """Prints one table; a measurement that did not finish (no file, or a file cut short)
    is reported instead of stopping the others."""
    try:
        show()
    except (OSError, ValueError, KeyError, IndexError, TypeError) as e:
        missing.append(title)
        print(f"\n({title}: not measured: {type(e).__name__} {e})")


def machine():
    try:
        gpu = subprocess.run(["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"],
                             capture_output=True, text=True).stdout.strip() or "?"
    except OSError:
        gpu = "?"
    print(f"machine: {gpu}, {os.cpu_count()} CPU cores, {platform.platform()}")


def wgpu_device():
    """What the wgpu measurements ran on, as the binary recorded it (absent before 30 November's
    twentieth session): a check whose wgpu ran on an emulated GPU measured the CPU."""
    found = []
    for name, rows in (("render_wgpu.json", lambda d: d["rows"]),
                       ("frames_wgpu.json", lambda d: [d]),
                       ("step_wgpu.json", lambda d: d)):
        try:
            found += [r["device"] for r in rows(load(name)) if r.get("device")]
        except (OSError, ValueError, KeyError, TypeError):
            pass
    devices = sorted(set(found))
    print(f"wgpu ran on: {', '.join(devices) if devices else 'not recorded'}")
    return [d for d in devices if d.startswith("emulated")]


def process_start():
    start = load("process_start.json")
    print(f"\na fresh process, four guitar steps (two step variants, one untimed step and one timed "
          f"each, kernels compiled on the way): {start['first_s']} s the first time, "
          f"{start['again_s']} s again")


def launch_costs():
    launches = {b: load(f"launches_{b}.json") for b in ("wgpu", "flex")}
    print("\n| µs each (a launch of the chain, a read, an upload) | wgpu | wgpu GB/s | "
          "wgpu launches an iteration | wgpu queued, µs an iteration | flex | flex GB/s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    rate = lambda r: f"{r['gb_per_s']:.2f}" if r.get("gb_per_s") else "-"
    for w, f in zip(launches["wgpu"], launches["flex"]):
        print(f"| {w['probe']} | {w['us_each']:.1f} | {rate(w)} | "
              f"{w['launches'] / w['iterations']:.1f} | {w['queued_us']:.1f} | {f['us_each']:.1f} | "
              f"{rate(f)} |")


def key(r):
    return (r["scene"], r["gaussians"], r["resolution"], r["pruning"])


def label(r):
    return f"{r['scene']} {r['gaussians']} {r['resolution']}² {r['pruning']}"


def grad_diff(r, f):
    """|dΦ wgpu − dΦ flex| / |dΦ flex| of one mask pass."""
    g, h = r.get("grad_pose", []), f.get("grad_pose", [])
    norm = math.sqrt(sum(x * x for x in h)) or 1.0
    return math.sqrt(sum((a - b) ** 2 for a, b in zip(g, h))) / norm if g and h else float("nan")


def measured(rows):
    return [r for r in rows if not r.get("skipped")]


def mask_passes():
    wgpu, flex = load("render_wgpu.json"), load("render_flex.json")
    flex_rows = {key(r): r for r in measured(flex["rows"])}
    print("\n| mask pass, fwd+bwd | wgpu ms | flex ms | wgpu/flex | launches | reads | KB up | "
          "TCE wgpu / flex | |dΦ| diff / |dΦ| |")
    print("|---|---:|---:|---:|---:|---:|---:|---|---:|")
    for r in measured(wgpu["rows"]):
        f = flex_rows.get(key(r))
        if f is None:
            continue
        diff = grad_diff(r, f)
        compared.append(key(r))
        tce_ok = abs(r["tce"] - f["tce"]) <= 1e-3 or (math.isnan(r["tce"]) and math.isnan(f["tce"]))
        if not (tce_ok and diff <= 1e-3 and abs(r["coverage"] - f["coverage"]) <= 1e-3):
            failed.append(f"{key(r)}: TCE {r['tce']} vs {f['tce']}, gradient {diff:.2e}")
        c = r.get("counts", {})
        print(f"| {label(r)} | {r['forward_backward_ms']:.2f} | {f['forward_backward_ms']:.2f} | "
              f"{r['forward_backward_ms'] / f['forward_backward_ms']:.2f} | "
              f"{c.get('launches', '-')} | {c.get('reads', '-')} | {c.get('bytes_up', 0) / 1024:.1f} | "
              f"{r['tce']:.6f} / {f['tce']:.6f} | {diff:.1e} |")


def variant_table(title, default, variant, name):
    """The wgpu mask passes against the same passes run another way (`name`), and its parity."""
    def show():
        wgpu = load("render_wgpu.json")
        flex_rows = {key(r): r for r in measured(load("render_flex.json")["rows"])}
        other = {key(r): r for r in measured(load(name)["rows"])}
        print(f"\n| {title}, fwd+bwd ms | {default} | {variant} | |dΦ| diff / |dΦ|, {variant} |")
        print("|---|---:|---:|---:|")
        for r in measured(wgpu["rows"]):
            o, f = other.get(key(r)), flex_rows.get(key(r))
            if o is None or f is None:
                continue
            diff = grad_diff(o, f)
            if not diff <= 1e-3:
                failed.append(f"{key(r)} {variant}: gradient {diff:.2e}")
            print(f"| {label(r)} | {r['forward_backward_ms']:.2f} | {o['forward_backward_ms']:.2f} | "
                  f"{diff:.1e} |")
    return show


def stage_table(title, rows, row_label, extra=None):
    """Each row's render stages, ms (and `extra`'s column)."""
    names = [n for n, _ in rows[0]["stages_ms"]] if rows else []
    head = " | ".join(names) + (f" | {extra[0]}" if extra else "")
    print(f"\n| {title} | {head} |")
    print("|---|" + "---:|" * (len(names) + (1 if extra else 0)))
    for r in rows:
        stages = dict(r["stages_ms"])
        cells = " | ".join(f"{stages.get(n, 0):.2f}" for n in names)
        if extra:
            cells += f" | {extra[1](r):.2f}"
        print(f"| {row_label(r)} | {cells} |")


def profiled_passes():
    rows = measured(load("render_wgpu_profiled.json")["rows"])
    stage_table("wgpu stages, ms, each kernel waited for", rows, label)


def output_frames():
    frames = {b: load(f"frames_{b}.json") for b in ("wgpu", "flex")}
    print("\n| 1080p output frame | wgpu ms | flex ms | wgpu launches | wgpu MB down |")
    print("|---|---:|---:|---:|---:|")
    same = lambda r: (r["scene"], r["gaussians"], r["width"], r["schedule"])
    for r in frames["wgpu"]["rows"]:
        f = next((x for x in frames["flex"]["rows"] if same(x) == same(r)), None)
        # A frame's counts (absent from binaries older than 30 November's fifteenth session).
        c = r.get("counts")
        per = lambda key: f"{c[key] / max(r['frames'], 1):.1f}" if c else "-"
        down = f"{c['bytes_down'] / max(r['frames'], 1) / 1e6:.1f}" if c else "-"
        # The SH degree rendered (absent before 30 November's sixteenth session).
        sh = f" SH {r['sh_degree']}" if "sh_degree" in r else ""
        if f:
            print(f"| {r['scene']} {r['gaussians']}{sh} {r['schedule']} | {r['frame_ms']:.0f} | "
                  f"{f['frame_ms']:.0f} | {per('launches')} | {down} |")


def step_row(title, r):
    c = r["counts"]
    print(f"| {title}, {r['passes']} | {r['ms_per_step']:.1f} | {c['launches']} | {c['reads']} | "
          f"{c.get('renders', '-')} | {c.get('segments', '-')} | {r['best_total']:.6f} |")


def steps():
    print("\n| optimisation step, guitar | ms | launches | reads | render calls | "
          "compositing workgroups | best loss |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    variants = [("wgpu, lists cut at 1024", "step_wgpu.json"), ("flex", "step_flex.json"),
                ("wgpu, lists whole", "step_wgpu_whole_lists.json")]
    variants += [(f"wgpu, lists cut at {n}", f"step_wgpu_segments_{n}.json") for n in (256, 512, 2048)]
    shown = 0
    for title, name in variants:
        try:
            rows = load(name)
        except (OSError, ValueError):
            print(f"| {title} | not measured | | | | | |")
            continue
        for r in rows:
            step_row(title, r)
            shown += 1
    if not shown:
        raise KeyError("no step was measured")


def host_share():
    """The unprofiled step's stages: decide and bin are the host's own work a step, the rest
    only queues device work (the device is waited for by the step's one read)."""
    rows = [r for b in ("wgpu", "flex") for r in load(f"step_{b}.json")]
    backend = lambda r: "wgpu" if r["counts"].get("launches") else "flex"
    stage_table("step, ms by stage as the host saw it (wgpu: decide and bin are the host's "
                "share; the other stages only queue)", rows,
                lambda r: f"{backend(r)}, {r['passes']}", ("ms a step", lambda r: r["ms_per_step"]))


def profiled_steps():
    rows = load("step_wgpu_profiled.json")
    stage_table("wgpu step, ms, each kernel waited for", rows, lambda r: f"guitar, {r['passes']}",
                ("ms a step", lambda r: r["ms_per_step"]))


def first_try():
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
            print(f"| {stage} on wgpu: launches, reads, MB down, MB up | {c['launches']}, "
                  f"{c['reads']}, {c['bytes_down'] / 2**20:.1f}, {c['bytes_up'] / 2**20:.1f} | |")
    for a, b in zip(w["windows"], f["windows"]):
        ta, tb = a.get("tce_middle"), b.get("tce_middle")
        print(f"| {a['name']}: verdict, TCE | {'pass' if a['pass'] else 'FAIL'}, {ta} | "
              f"{'pass' if b['pass'] else 'FAIL'}, {tb} |")
        compared.append(a["name"])
        if a["pass"] != b["pass"]:
            failed.append(f"guitar {a['name']}: verdicts differ")
    print(f"\nspeed-up of the whole run: {f['total_s'] / w['total_s']:.2f}x")


machine()
emulated = wgpu_device()
section("process start", process_start)
section("launch, read and upload costs", launch_costs)
section("mask passes", mask_passes)
section("backward's entry sums", variant_table(
    "backward's entry sums", "pipelined", "one at a time", "render_wgpu_one_at_a_time.json"))
section("compositing kernels unchecked", variant_table(
    "compositing kernels unchecked", "checked", "unchecked", "render_wgpu_unchecked.json"))
section("tile lists in the backward", variant_table(
    "tile lists in the backward", "cut", "whole", "render_wgpu_whole_lists.json"))
section("mask passes, each kernel waited for", profiled_passes)
section("output frames", output_frames)
section("optimisation steps", steps)
section("the host's share of a step", host_share)
section("optimisation step, each kernel waited for", profiled_steps)
section("first-try guitar", first_try)
print(f"\nJSON in {out}")
if len(sys.argv) > 2:
    print(f"the check's measurements took {int(sys.argv[2]) / 60:.1f} minutes")
if emulated:
    print(f"WARNING: wgpu ran on {', '.join(emulated)}, not a GPU: its figures are the CPU's "
          "(is the GPU's Vulkan ICD installed and found? `vulkaninfo --summary`)")
if missing:
    print("not measured (the check stopped before them, or they failed): " + ", ".join(missing))
if failed:
    print("PARITY FAILED:\n  " + "\n  ".join(failed))
    sys.exit(1)
if not compared:
    print("parity: nothing to compare (no mask pass or verdict was measured on both backends)")
else:
    print("parity: wgpu matches flex on every mask pass and every verdict measured")
