#!/usr/bin/env python3
"""Adversarial trial of the splatraj CLI (issue 27: nothing hangs, nothing silent, nothing destroyed).

How to run:

    python3 scripts/adversarial_trial.py /path/to/splatraj [--work /tmp/trial/work]
        [--only SUBSTRING] [--budget-s 3300] [--mem-gb 6] [--json results.json]

    The binary should be a release build. The trial needs the repository's `configs/` (found
    beside this script) and `/work/shared/data` (or `$SPLATRAJ_DATA`) for the real scene files.
    Run it as root to test device nodes made with mknod (else FIFOs and real read-only /dev
    inputs are used and the device outputs are skipped). Cases run one at a time.

What it checks: every command of the CLI (scene info/convert/demo/lift-masks, render, query,
run, pose, bench *, study (merge), encode-text, export, render-path, report) against bad inputs,
faults and signals: corrupt, truncated and hostile scene files of every readable format (binary
and ASCII PLY, compressed PLY, SPZ, SOG, .splat, .ksplat), NaN/inf/negative/huge values and wrong
types in the config keys, special files (device nodes, FIFOs, directories, symlinks) as inputs
and outputs, output into existing folders (twice, concurrently), huge sizes, SIGINT/SIGTERM/
SIGKILL at several moments, malformed trajectory/camera files and malformed run folders.

Each case runs under a memory cap (`prlimit --as`) and a timeout, in its own scratch folder
(removed afterwards), and is classified as:

    ok         clear error (non-zero exit naming the file/key), or correct work where work is due
    PANIC      exit 101 or "panicked"
    ABORT      exit 134 / SIGABRT / "memory allocation failed" / killed by another signal
    HANG       timed out
    EXIT0      exit 0 on bad input (or a huge size accepted without refusal or warning)
    DESTROYED  a special file or an unrelated file was changed or replaced
    HALF       a partial output left (`.partial`, temporary files, output of a refused command,
               stale frames mixed with new ones)
    UNCLEAR    the error message names none of the expected words (the key, flag or file)

The summary (counts per class, then every non-ok case with its command, what happened and what
was expected) is printed at the end and written as JSON with --json.
"""

import argparse
import gzip
import json
import os
import re
import shutil
import signal
import stat
import struct
import subprocess
import sys
import time
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DATA = Path(os.environ.get("SPLATRAJ_DATA", "/work/shared/data"))
IS_ROOT = os.geteuid() == 0

# ---------------------------------------------------------------------------------------------
# Cases


class Case:
    """One command with its expectation: `fail` (refused, naming one of `names`), `ok` (work
    done, exit 0 or 3 = a verdict), or `refuse_or_warn` (a huge size: refused, or accepted with a
    warning that gives an estimate)."""

    def __init__(self, name, argv, expect="fail", names=(), timeout=20, outs=(), guards=(),
                 setup=None, check=None, stdin=None, runner=None):
        self.name = name
        self.argv = argv
        self.expect = expect
        self.names = [n.lower() for n in names]
        self.timeout = timeout
        self.outs = outs  # paths (relative to the case folder) that must not exist after a refusal
        self.guards = guards  # paths whose identity and content must not change
        self.setup = setup  # callable(work) run before the command
        self.check = check  # callable(work, result) -> (class, note) or None, after the command
        self.runner = runner  # callable(case, work) -> result, instead of one plain run


CASES = []


def case(*a, **k):
    CASES.append(Case(*a, **k))


# ---------------------------------------------------------------------------------------------
# Running


class Result:
    def __init__(self, rc, out, secs, timed_out, note=""):
        self.rc, self.out, self.secs, self.timed_out, self.note = rc, out, secs, timed_out, note


def launch(binary, argv, cwd, mem_gb, stdin=subprocess.DEVNULL, env=None):
    argv = [a.replace("{W}", str(cwd)) for a in argv]
    cmd = ["prlimit", f"--as={int(mem_gb * 2**30)}", "--", binary] + argv
    return subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=stdin, start_new_session=True,
                            env=None if env is None else {**os.environ, **env})


def with_env(ctx, env):
    """A runner: the case's command with `env` added to the environment."""
    def go(c, work):
        t0 = time.time()
        return finish(launch(ctx.binary, c.argv, work, ctx.mem_gb, env=env), c.timeout, t0)
    return go


def finish(p, timeout, t0):
    timed_out = False
    try:
        out, _ = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        timed_out = True
        kill_group(p.pid)
        out, _ = p.communicate()
    return Result(p.returncode, out.decode("utf-8", "replace"), time.time() - t0, timed_out)


def kill_group(pgid):
    try:
        os.killpg(pgid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def leftover_processes(sid):
    """Processes still in the session the case started (orphaned children)."""
    try:
        out = subprocess.run(["ps", "-e", "-o", "pid=,sid=,comm="], capture_output=True,
                             text=True).stdout
    except OSError:
        return []
    return [line.strip() for line in out.splitlines()
            if len(line.split()) >= 2 and line.split()[1] == str(sid)]


def run_plain(ctx, c, work):
    t0 = time.time()
    p = launch(ctx.binary, c.argv, work, ctx.mem_gb)
    r = finish(p, c.timeout, t0)
    left = leftover_processes(p.pid)
    if left:
        r.note += f" orphaned processes: {left}"
        for line in left:
            try:
                os.kill(int(line.split()[0]), signal.SIGKILL)
            except (ProcessLookupError, ValueError):
                pass
    return r


def identity(path):
    """What must not change about a guarded path: its type, device, inode and (regular) bytes."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    ident = (stat.S_IFMT(st.st_mode), st.st_rdev, st.st_ino)
    if stat.S_ISREG(st.st_mode) and st.st_size < 50 * 2**20:
        ident += (Path(path).read_bytes(),)
    if stat.S_ISLNK(st.st_mode):
        ident += (os.readlink(path),)
    return ident


def partial_files(work):
    found = []
    for root, dirs, files in os.walk(work):
        for n in dirs + files:
            low = n.lower()
            if ".partial" in low or low.endswith(".tmp") or low.startswith(".tmp") \
                    or ".tmp." in low:
                found.append(os.path.relpath(os.path.join(root, n), work))
    return found


def classify(c, r, work, guards_before):
    out_l = r.out.lower()
    for g, before in guards_before.items():
        if identity(os.path.join(work, g)) != before:
            return "DESTROYED", f"{g} was changed or replaced"
    if r.timed_out:
        return "HANG", f"no exit within {c.timeout} s"
    if r.rc == 101 or "panicked" in out_l:
        return "PANIC", "panic"
    if r.rc in (134, -6) or "memory allocation" in out_l or "allocation failed" in out_l:
        return "ABORT", f"rc {r.rc}"
    if r.rc is not None and r.rc < 0 and r.rc != -signal.SIGKILL:
        return "ABORT", f"killed by signal {-r.rc}"
    if r.rc == -signal.SIGKILL:
        return "ABORT", "killed by SIGKILL (memory cap?)"
    if c.check:
        verdict = c.check(work, r)
        if verdict:
            return verdict
    parts = partial_files(work)
    if parts:
        return "HALF", f"left {parts[:5]}"
    if "orphaned" in r.note:
        return "HALF", r.note
    if c.expect == "fail":
        if r.rc == 0:
            return "EXIT0", "exit 0 on bad input"
        for o in c.outs:
            if os.path.exists(os.path.join(work, o)):
                return "HALF", f"refused but left {o}"
        clap = r.rc == 2 and "usage:" in out_l and "error:" in out_l
        if c.names and not clap and not any(n in out_l for n in c.names):
            return "UNCLEAR", f"message names none of {c.names}"
        return "ok", ""
    if c.expect == "any":
        if r.rc not in (0, 3) and c.names and not any(n in out_l for n in c.names):
            return "UNCLEAR", f"message names none of {c.names}"
        return "ok", ""
    if c.expect == "refuse_or_warn":
        if r.rc == 0 and not ("warning" in out_l and any(
                w in out_l for w in ("estimat", "about", "limit", "time", "memory"))):
            return "EXIT0", "huge size accepted without refusal or estimate warning"
        if r.rc != 0 and c.names and not any(n in out_l for n in c.names):
            return "UNCLEAR", f"message names none of {c.names}"
        return "ok", ""
    # expect ok
    if r.rc not in (0, 3):
        return "FAILED", f"valid work failed with rc {r.rc}"
    return "ok", ""


# ---------------------------------------------------------------------------------------------
# Fixtures (built once under work/fx)


def make_fixtures(ctx):
    fx = ctx.fx
    fx.mkdir(parents=True, exist_ok=True)
    b = ctx.binary
    subprocess.run([b, "scene", "demo", "--out", str(fx / "demo.ply"), "--gaussians", "5000"],
                   check=True, capture_output=True)
    (fx / "small.toml").write_text(SMALL_TOML.format(runs=fx / "runs", scene=""))
    (fx / "slow.toml").write_text(SLOW_TOML.format(runs=fx / "runs"))
    r = subprocess.run([b, "run", str(fx / "small.toml"), "--quiet"], capture_output=True,
                       text=True)
    runs = sorted((fx / "runs" / "small").iterdir())
    if not runs:
        sys.exit(f"fixture run failed: {r.stdout}{r.stderr}")
    shutil.copytree(runs[-1], fx / "run")
    shutil.copy(REPO / "configs" / "cameras" / "demo_mug.json", fx / "camera.json")
    # the same trajectory as a plain file (render-path/export inputs)
    shutil.copy(fx / "run" / "trajectory.json", fx / "trajectory.json")
    # an interrupted run (SIGINT while optimising), for --resume
    p = subprocess.Popen([b, "run", str(fx / "slow.toml"), "--quiet", "--set",
                          f'output.runs_dir="{fx}/interrupted-runs"'],
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(2.5)
    p.send_signal(signal.SIGINT)
    p.wait(timeout=60)
    stopped = sorted((fx / "interrupted-runs" / "slow").iterdir())
    if not stopped or not (stopped[-1] / "checkpoint.json").exists():
        sys.exit("fixture: the interrupted run left no checkpoint.json")
    shutil.copytree(stopped[-1], fx / "interrupted")
    # a small binary PLY scene written by hand (independent of the reader)
    write_ply(fx / "hand.ply", ply_rows(64))
    write_ply(fx / "hand_ascii.ply", ply_rows(16), fmt="ascii")


SMALL_TOML = """name = "small"
seed = 7
backend = "flex"
[scene]
demo = {{ gaussians = 5000, seed = 7 }}
[targets]
source = "labels"
[[queries]]
text = "red mug"
[[queries]]
text = "green ball"
[camera]
width = 32
height = 24
fov_x = 60.0
target_ratio = 0.15
[trajectory]
kind = "rbf"
centres_per_window = 2
[optimiser]
iterations = 3
samples_per_window = 2
learning_rate = 0.02
path_samples = 8
[start]
kind = "objects"
restarts = 1
[output]
runs_dir = "{runs}"
frames = 6
width = 32
height = 24
"""

# A run of several seconds in each phase, for the signals.
# About 7 s optimising and 5 s rendering frames on 2 shared cores.
SLOW_TOML = SMALL_TOML.replace("iterations = 3", "iterations = 4000").replace(
    "frames = 6\nwidth = 32\nheight = 24\n", "frames = 240\nwidth = 320\nheight = 240\n"
).replace('name = "small"', 'name = "slow"')


PLY_PROPS = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1",
             "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


def ply_rows(n, value=None):
    rows = []
    for i in range(n):
        r = [((i * 37) % 11) / 10 - 0.5, ((i * 13) % 7) / 7 - 0.5, ((i * 5) % 3) / 3,
             0.5, 0.1, -0.2, 1.0, -3.0, -3.0, -3.0, 1.0, 0.0, 0.0, 0.0]
        rows.append(r)
    if value is not None:
        rows[n // 2] = [value] * len(PLY_PROPS)
    return rows


def ply_header(n, fmt="binary_little_endian", props=PLY_PROPS, ptype="float", extra=""):
    h = f"ply\nformat {fmt} 1.0\n{extra}element vertex {n}\n"
    h += "".join(f"property {ptype} {p}\n" for p in props)
    return h + "end_header\n"


def write_ply(path, rows, fmt="binary_little_endian", count=None, props=PLY_PROPS):
    n = len(rows) if count is None else count
    head = ply_header(n, fmt, props).encode()
    if fmt == "ascii":
        body = "".join(" ".join(repr(float(v)) for v in r) + "\n" for r in rows).encode()
    else:
        e = "<" if fmt == "binary_little_endian" else ">"
        body = b"".join(struct.pack(e + "f" * len(r), *r) for r in rows)
    Path(path).write_bytes(head + body)


def make_special(work, name, kind):
    """A special file in the case folder: `full`, `null`, `zero` (device nodes), `fifo`, `dir`,
    `link-full` (symlink to a device node), `link-zero`."""
    p = work / name
    if kind in ("full", "zero", "null"):
        minor = {"full": 7, "zero": 5, "null": 3}[kind]
        if IS_ROOT:
            os.mknod(p, 0o666 | stat.S_IFCHR, os.makedev(1, minor))
        else:
            os.symlink(f"/dev/{kind}", p)
    elif kind == "fifo":
        os.mkfifo(p)
    elif kind == "dir":
        p.mkdir()
    elif kind.startswith("link-"):
        target = make_special(work, name + ".target", kind[5:])
        os.symlink(target, p)
    return p


SPECIALS = ["zero", "fifo", "dir", "link-zero"]
OUT_SPECIALS = ["full", "null", "fifo", "link-full"]


# ---------------------------------------------------------------------------------------------
# Hostile scene files


def hostile_scenes(fx):
    """(file name, bytes or callable(path)) of corrupt, truncated and hostile scenes."""
    s = []
    good = (fx / "hand.ply").read_bytes()
    head_len = good.index(b"end_header\n") + len(b"end_header\n")
    rows = ply_rows(64)
    body = good[head_len:]
    s.append(("empty.ply", b""))
    s.append(("only-magic.ply", b"ply\n"))
    s.append(("no-end-header.ply", ply_header(64).replace("end_header\n", "").encode() + body))
    s.append(("truncated-body.ply", good[: head_len + len(body) // 2]))
    s.append(("truncated-header.ply", good[: head_len // 2]))
    s.append(("count-huge.ply", ply_header(10**12).encode() + body))
    s.append(("count-u64max.ply", ply_header(2**64 - 1).encode() + body))
    s.append(("count-negative.ply", ply_header(-5).encode() + body))
    s.append(("count-text.ply", ply_header("abc").encode() + body))
    s.append(("count-zero.ply", ply_header(0).encode()))
    s.append(("many-props.ply", ply_header(1, props=[f"p{i}" for i in range(100000)]).encode()))
    s.append(("header-2mib.ply", (ply_header(64, extra="comment " + "x" * (2 * 2**20) + "\n")
                                  ).encode() + body))
    s.append(("long-line-no-newline.ply", b"ply\nformat binary_little_endian 1.0\ncomment "
              + b"y" * (8 * 2**20)))
    s.append(("dup-prop.ply", ply_header(64, props=PLY_PROPS + ["x"]).encode() + body))
    s.append(("unknown-type.ply", ply_header(64, ptype="float128").encode() + body))
    s.append(("list-prop.ply", ply_header(64, extra="").replace(
        "property float x\n", "property list uchar float x\n").encode() + body))
    s.append(("missing-x.ply", ply_header(64, props=PLY_PROPS[1:]).encode() + body))
    s.append(("no-vertex.ply", b"ply\nformat binary_little_endian 1.0\nelement face 3\n"
              b"property list uchar int vertex_indices\nend_header\n" + b"\0" * 30))
    s.append(("bad-format.ply", ply_header(64, fmt="binary_middle_endian").encode() + body))
    s.append(("bad-version.ply", ply_header(64).replace("1.0", "9.9").encode() + body))
    for label, v in (("nan", float("nan")), ("inf", float("inf")), ("huge", 1e38)):
        p = fx / f"values-{label}.ply"
        write_ply(p, ply_rows(64, v))
        s.append((p.name, p.read_bytes()))
    zero_q = [list(r) for r in rows]
    zero_q[3][10:14] = [0, 0, 0, 0]
    s.append(("zero-quat.ply", ply_header(64).encode() + b"".join(
        struct.pack("<" + "f" * 14, *r) for r in zero_q)))
    s.append(("trailing-garbage.ply", good + b"\x01" * 1000))
    s.append(("extra-rows.ply", ply_header(32).encode() + body))
    s.append(("big-endian-lie.ply", ply_header(64, fmt="binary_big_endian").encode() + body))
    asc = (fx / "hand_ascii.ply").read_bytes()
    ahead = ply_header(16, "ascii").encode()
    arows = asc[len(ahead):].split(b"\n")
    arows[3] = b" ".join(arows[3].split()[:-1])
    s.append(("ascii-short-row.ply", ahead + b"\n".join(arows)))
    s.append(("ascii-long-row.ply", asc.replace(b" 0.0\n", b" 0.0 7 7\n", 1)))
    s.append(("ascii-nan.ply", ply_header(2, "ascii").encode() + b"nan " * 14 + b"\n"
              + b"1 " * 14 + b"\n"))
    s.append(("ascii-text.ply", ply_header(2, "ascii").encode() + b"a b c\n1 2 3\n"))
    s.append(("ascii-truncated.ply", asc[: len(asc) - 40]))
    s.append(("ascii-nonutf8.ply", ply_header(1, "ascii").encode() + b"\xff\xfe" * 20 + b"\n"))
    s.append(("ascii-crlf.ply", asc.replace(b"\n", b"\r\n")))
    s.append(("random.ply", os.urandom(4096)))
    s.append(("text.ply", b"hello world\n" * 100))
    s.append(("nul-bytes.ply", b"\0" * 10000))
    # compressed PLY
    cpath = DATA / "test.compressed.ply"
    if cpath.exists():
        c = cpath.read_bytes()
        ch = c.index(b"end_header\n") + len(b"end_header\n")
        s.append(("c-truncated-half.compressed.ply", c[: len(c) // 2]))
        s.append(("c-truncated-header.compressed.ply", c[: ch - 5]))
        s.append(("c-truncated-one.compressed.ply", c[:-1]))
        header = c[:ch].decode("latin-1")
        import re
        m = re.search(r"element chunk (\d+)", header)
        v = re.search(r"element vertex (\d+)", header)
        if m:
            s.append(("c-chunks-huge.compressed.ply",
                      header.replace(m.group(0), "element chunk 4000000000").encode("latin-1")
                      + c[ch:]))
            s.append(("c-chunks-zero.compressed.ply",
                      header.replace(m.group(0), "element chunk 0").encode("latin-1") + c[ch:]))
        if v:
            s.append(("c-vertex-more.compressed.ply",
                      header.replace(v.group(0), f"element vertex {int(v.group(1)) * 300}"
                                     ).encode("latin-1") + c[ch:]))
            s.append(("c-vertex-huge.compressed.ply",
                      header.replace(v.group(0), "element vertex 99999999999").encode("latin-1")
                      + c[ch:]))
        s.append(("c-nan-chunk.compressed.ply",
                  c[:ch] + struct.pack("<f", float("nan")) * 18 + c[ch + 72:]))
    # SPZ (gzip of a 16-byte header: magic, version, count, sh degree, fractional bits, flags)
    spz = DATA / "biker.spz"
    if spz.exists():
        raw = spz.read_bytes()
        s.append(("truncated.spz", raw[: len(raw) // 3]))
        s.append(("gzip-garbage.spz", b"\x1f\x8b\x08\x00" + os.urandom(2000)))
        gz = raw[:2] == b"\x1f\x8b"
        inner = gzip.decompress(raw) if gz else raw
        wrap = gzip.compress if gz else (lambda x: x)
        s.append(("inner-truncated.spz", wrap(inner[: len(inner) // 2])))
        s.append(("v4-truncated-32.spz", raw[:32]))
        s.append(("v2-gzip-of-v4.spz", gzip.compress(raw)))

        def hdr(version=inner[4], n=None, deg=None, frac=None, magic=None, rest=inner[16:]):
            h = bytearray(inner[:16])
            if magic is not None:
                h[0:4] = magic
            h[4:8] = struct.pack("<I", version)
            if n is not None:
                h[8:12] = struct.pack("<I", n)
            if deg is not None:
                h[12] = deg
            if frac is not None:
                h[13] = frac
            return wrap(bytes(h) + rest)
        s.append(("count-huge.spz", hdr(n=2**32 - 1)))
        s.append(("count-zero.spz", hdr(n=0, rest=b"")))
        s.append(("sh-degree-9.spz", hdr(deg=9)))
        s.append(("frac-bits-99.spz", hdr(frac=99)))
        s.append(("version-99.spz", hdr(version=99)))
        s.append(("bad-magic.spz", hdr(magic=b"XXXX")))
        s.append(("header-only.spz", gzip.compress(inner[:16])))
        s.append(("v2-count-huge.spz", gzip.compress(b"NGSP" + struct.pack("<II", 2, 2**31)
                                                     + b"\0\x0c\0\0" + b"\0" * 4000)))
        s.append(("v2-short-body.spz", gzip.compress(b"NGSP" + struct.pack("<II", 2, 1000)
                                                     + b"\0\x0c\0\0" + b"\0" * 4000)))
    s.append(("bomb.spz", gzip.compress(b"NGSP" + struct.pack("<I", 2) + struct.pack("<I", 1000)
                                        + b"\0\x0c\0\0" + b"\0" * (300 * 2**20), 9)))
    # SPZ v4 whose zstd streams are run-length blocks: a 37 KB file whose valid streams decode
    # to 60 M Gaussians (issue 39); refused for its ratio before anything is decoded.
    def zstd_rle(n):
        frame = bytearray(struct.pack("<I", 0xFD2FB528) + bytes([0x00, 0x38]))  # 128 KiB window
        while n > 0:
            size = min(n, 1 << 17)
            n -= size
            frame += struct.pack("<I", (n == 0) | (1 << 1) | (size << 3))[:3] + b"\0"
        return bytes(frame)
    count = 60_000_000
    streams = [zstd_rle(per * count) for per in (9, 1, 3, 3, 4)]
    v4 = bytearray(b"NGSP" + struct.pack("<II", 4, count) + bytes([0, 12, 0, len(streams)])
                   + struct.pack("<I", 32) + b"\0" * 12)
    for stream, per in zip(streams, (9, 1, 3, 3, 4)):
        v4 += struct.pack("<QQ", len(stream), per * count)
    s.append(("v4-zstd-rle-60M.spz", bytes(v4) + b"".join(streams)))
    # SOG (zip of meta.json and WebP images)
    sog = DATA / "narcissus.sog"
    if sog.exists():
        raw = sog.read_bytes()
        s.append(("truncated.sog", raw[: len(raw) // 2]))
        s.append(("random.sog", os.urandom(5000)))
        with zipfile.ZipFile(sog) as z:
            names = z.namelist()
            files = {n: z.read(n) for n in names}
        meta = json.loads(files["meta.json"])

        def sog_with(name, **changes):
            def build(path):
                with zipfile.ZipFile(path, "w") as z:
                    for n, data in files.items():
                        if n in changes:
                            data = changes[n]
                            if data is None:
                                continue
                        z.writestr(n, data)
            return (name, build)
        s.append(sog_with("no-meta.sog", **{"meta.json": None}))
        s.append(sog_with("meta-garbage.sog", **{"meta.json": b"{not json"}))
        m2 = json.loads(json.dumps(meta))
        if "count" in m2:
            m2["count"] = 10**12
        elif "means" in m2 and "shape" in m2["means"]:
            m2["means"]["shape"] = [10**12, 3]
        s.append(sog_with("meta-count-huge.sog", **{"meta.json": json.dumps(m2).encode()}))
        m3 = json.loads(json.dumps(meta))
        m3["version"] = 99
        s.append(sog_with("meta-version-99.sog", **{"meta.json": json.dumps(m3).encode()}))
        webps = [n for n in names if n.endswith(".webp")]
        if webps:
            s.append(sog_with("webp-garbage.sog", **{webps[0]: b"RIFF\0\0\0\0WEBPjunk"}))
            s.append(sog_with("webp-missing.sog", **{webps[0]: None}))
        s.append(("meta-nan.sog", lambda path: zip_meta_nan(path, files)))
    s.append(("zipbomb.sog", zip_bomb))
    # .splat (32-byte records)
    rec = struct.pack("<3f3f4B4B", 0.1, 0.2, 0.3, 0.01, 0.01, 0.01, 200, 10, 10, 255,
                      255, 128, 128, 128)
    s.append(("empty.splat", b""))
    s.append(("ragged.splat", rec * 10 + b"\1" * 7))
    s.append(("nan.splat", struct.pack("<3f", *[float("nan")] * 3) + rec[12:] + rec * 9))
    s.append(("zero-scale.splat", rec[:12] + struct.pack("<3f", 0, 0, 0) + rec[24:] + rec * 3))
    s.append(("random.splat", os.urandom(32 * 100)))
    s.append(("text.splat", b"this is not a splat file at all!" * 10))
    # .ksplat (4096-byte header, 1024-byte section headers)
    def ksplat(major=0, minor=1, max_sec=1, sec=1, max_splats=10, splats=10, level=0, tail=b""):
        h = bytearray(4096)
        h[0], h[1] = major, minor
        struct.pack_into("<IIIIH", h, 4, max_sec, sec, max_splats, splats, level)
        return bytes(h) + tail
    s.append(("random.ksplat", os.urandom(8192)))
    s.append(("header-only.ksplat", ksplat()))
    s.append(("sections-huge.ksplat", ksplat(max_sec=2**32 - 1, sec=2**32 - 1)))
    s.append(("splats-huge.ksplat", ksplat(max_splats=2**32 - 1, splats=2**32 - 1,
                                           tail=b"\0" * 1024)))
    s.append(("level-7.ksplat", ksplat(level=7, tail=b"\0" * 1024)))
    s.append(("version-9.ksplat", ksplat(major=9, tail=b"\0" * 1024)))
    s.append(("short.ksplat", b"\0\1\0\0"))
    s.append(("section-lie.ksplat", ksplat(tail=struct.pack("<IIIIIHHf", 10**9, 10**9, 256, 1,
                                                            2**31, 0, 0, 1.0) + b"\0" * 1000)))
    return s


def zip_meta_nan(path, files):
    meta = files["meta.json"].decode()
    import re
    meta = re.sub(r"-?\d+\.\d+", "NaN", meta, count=6)
    with zipfile.ZipFile(path, "w") as z:
        for n, d in files.items():
            z.writestr(n, meta if n == "meta.json" else d)


def zip_bomb(path):
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("meta.json", b" " * (400 * 2**20))


def webp_constant(w, h, argb=(255, 128, 128, 128)):
    """A lossless WebP (VP8L) of w × h texels of one colour, written by hand: every prefix code
    is a simple code of one symbol, which takes no bits, so any size is a few dozen bytes."""
    bits = []

    def put(v, n):
        bits.extend((v >> i) & 1 for i in range(n))
    put(w - 1, 14), put(h - 1, 14), put(1, 1), put(0, 3)  # size, alpha used, version 0
    put(0, 1), put(0, 1), put(0, 1)  # no transform, no colour cache, no meta prefix codes
    a, r, g, b = argb
    for symbol in (g, r, b, a, 0):  # green, red, blue, alpha, distance
        put(1, 1), put(0, 1), put(1, 1), put(symbol, 8)  # simple code, 1 symbol, 8 bits
    data = b"\x2f" + bytes(sum(bit << i for i, bit in enumerate(bits[k:k + 8]))
                           for k in range(0, len(bits), 8))
    chunk = b"VP8L" + struct.pack("<I", len(data)) + data + b"\0" * (len(data) % 2)
    return b"RIFF" + struct.pack("<I", 4 + len(chunk)) + b"WEBP" + chunk


def sog_of(count, sizes):
    """A SOG v2 bundle of `count` Gaussians whose images are constant WebPs of `sizes`
    (image name -> (w, h)); no meta.json codebook is taken from a real file."""
    book = [round(-6 + 6 * i / 255, 4) for i in range(256)]
    meta = {"version": 2, "count": count,
            "means": {"mins": [-1, -1, -1], "maxs": [1, 1, 1],
                      "files": ["means_l.webp", "means_u.webp"]},
            "scales": {"codebook": book, "files": ["scales.webp"]},
            "quats": {"files": ["quats.webp"]},
            "sh0": {"codebook": [round(-2 + 4 * i / 255, 4) for i in range(256)],
                    "files": ["sh0.webp"]}}

    def build(path):
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("meta.json", json.dumps(meta))
            for name, (w, h) in sizes.items():
                z.writestr(name, webp_constant(w, h))
    return build


def transforms_from_inria(run, angle):
    """The fixture run's INRIA cameras as a nerfstudio transforms.json with `camera_angle_x`
    (radians) instead of focal lengths (OpenCV camera axes turned to OpenGL's)."""
    frames = []
    cams = json.loads((Path(run) / "exports/inria/cameras.json").read_text())
    for c in cams:
        rot, pos = c["rotation"], c["position"]
        m = [[rot[i][0], -rot[i][1], -rot[i][2], pos[i]] for i in range(3)] + [[0, 0, 0, 1]]
        frames.append({"file_path": f"images/{c['img_name']}.png", "transform_matrix": m})
    return json.dumps({"camera_angle_x": angle, "w": cams[0]["width"], "h": cams[0]["height"],
                       "frames": frames})


def names_all(*words, unless=()):
    """A check: a refusal must name every one of `words` and none of `unless` (a flag or file
    the user did not give)."""
    def check(work, r):
        if r.rc in (0, 3, None):
            return None
        low = r.out.lower()
        missing = [w for w in words if w.lower() not in low]
        if missing:
            return ("UNCLEAR", f"message does not name {missing}")
        wrong = [w for w in unless if w.lower() in low]
        if wrong:
            return ("UNCLEAR", f"message names {wrong}, which the command did not give")
        return None
    return check


# ---------------------------------------------------------------------------------------------
# Case definitions


def define_cases(ctx):
    fx = str(ctx.fx)
    scene = f"{fx}/demo.ply"
    small = f"{fx}/small.toml"
    run = f"{fx}/run"
    traj = f"{fx}/trajectory.json"
    cam = f"{fx}/camera.json"

    # --- hostile scenes: every file through `scene info`, a selection through convert/render
    for fname, content in hostile_scenes(ctx.fx):
        def setup(work, fname=fname, content=content):
            p = work / fname
            if callable(content):
                content(p)
            else:
                p.write_bytes(content)
        # accepted on purpose: an empty scene described, trailing bytes and a bomb's tail warned
        # about (README), CRLF line ends
        lenient = fname in ("count-zero.ply", "trailing-garbage.ply", "ascii-crlf.ply",
                            "bomb.spz")
        case(f"scene info {fname}", ["scene", "info", fname], names=[fname], setup=setup,
             timeout=20, expect="any" if lenient else "fail")
    for fname, content in hostile_scenes(ctx.fx)[::4]:
        def setup(work, fname=fname, content=content):
            p = work / fname
            content(p) if callable(content) else p.write_bytes(content)
        lenient = fname in ("trailing-garbage.ply", "ascii-crlf.ply", "bomb.spz")
        case(f"scene convert {fname}", ["scene", "convert", fname, "out.ply"], names=[fname],
             setup=setup, outs=[] if lenient else ["out.ply"],
             expect="any" if lenient else "fail")
        case(f"render --scene {fname}", ["render", "--scene", fname, "--camera", cam,
                                         "--label", "1", "--width", "32"], names=[fname],
             setup=setup)

    # --- special files as every input path
    inputs = {
        "scene info": lambda p: ["scene", "info", p],
        "scene convert in": lambda p: ["scene", "convert", p, "out.ply"],
        "scene info --labels": lambda p: ["scene", "info", scene, "--labels", p],
        "render --scene": lambda p: ["render", "--scene", p, "--camera", cam, "--label", "1"],
        "render --camera": lambda p: ["render", "--scene", scene, "--camera", p, "--label", "1"],
        "render --mask": lambda p: ["render", "--scene", scene, "--camera", cam, "--mask", p],
        "run config": lambda p: ["run", p, "--check"],
        "pose config": lambda p: ["pose", p],
        "study config": lambda p: ["study", p, "--dry-run"],
        "query --scene": lambda p: ["query", "--scene", p, "--query", "red mug", "--out", "q"],
        "query --config": lambda p: ["query", "--config", p, "--out", "q"],
        "query --features": lambda p: ["query", "--scene", scene, "--features", p,
                                       "--query", "mug", "--out", "q"],
        "query --phrases": lambda p: ["query", "--scene", scene, "--phrases", p,
                                      "--query", "mug", "--out", "q"],
        "export input": lambda p: ["export", p, "--format", "colmap", "--out", "e"],
        "render-path scene": lambda p: ["render-path", p, traj, "--out", "rp"],
        "render-path path": lambda p: ["render-path", scene, p, "--out", "rp"],
        "report run": lambda p: ["report", p],
        "report --scene": lambda p: ["report", "run", "--scene", p],
        "encode-text --text-encoder": lambda p: ["encode-text", "--text-encoder", p,
                                                 "--out", "t.json", "mug"],
        "lift-masks --cameras": lambda p: ["scene", "lift-masks", "--scene", scene,
                                           "--cameras", p, "--masks", "m", "--out", "l.json"],
        "config scene.path": lambda p: ["run", "c.toml", "--check"],
        "config start.trajectory": lambda p: ["run", "c.toml", "--check"],
        "config queries mask": lambda p: ["run", "c.toml", "--check"],
    }
    for label, mk in inputs.items():
        for kind in SPECIALS:
            def setup(work, kind=kind, label=label):
                make_special(work, "sp", kind)
                if label.startswith("report --scene"):
                    shutil.copytree(run, work / "run")
                text = Path(small).read_text()
                if label == "config scene.path":
                    (work / "c.toml").write_text(text.replace(
                        "demo = { gaussians = 5000, seed = 7 }", 'path = "sp"'))
                elif label == "config start.trajectory":
                    (work / "c.toml").write_text(text.replace(
                        'kind = "objects"', 'kind = "objects"\ntrajectory = "sp"'))
                elif label == "config queries mask":
                    (work / "c.toml").write_text(text.replace(
                        'text = "red mug"', 'text = "red mug"\nmask = "sp"'))
            case(f"{label} <- {kind}", mk("sp"), names=["sp"], setup=setup, timeout=20,
                 guards=["sp"], outs=["out.ply", "q", "e", "rp", "t.json", "l.json"])

    # --- special files and odd places as every output path
    outputs = {
        "scene convert out": lambda p: ["scene", "convert", scene, p],
        "scene convert out .spz": lambda p: ["scene", "convert", scene, p, "--format", "spz"],
        "scene demo --out": lambda p: ["scene", "demo", "--out", p, "--gaussians", "2000"],
        "query --out": lambda p: ["query", "--scene", scene, "--query", "red mug", "--out", p,
                                  "--width", "32", "--height", "24"],
        "export --out": lambda p: ["export", run, "--format", "nerfstudio", "--out", p],
        "render-path --out": lambda p: ["render-path", scene, traj, "--out", p, "--no-video",
                                        "--width", "32", "--seconds", "0.1"],
        "study --out": lambda p: ["study", small, "--out", p, "--vary",
                                  "optimiser.iterations=1,2", "--quiet"],
        "run runs_dir": lambda p: ["run", small, "--quiet", "--set",
                                   f'output.runs_dir="{{W}}/{p}"'],
        "lift-masks --out": lambda p: ["scene", "lift-masks", "--scene", scene, "--cameras",
                                       f"{run}/exports/inria/cameras.json", "--masks", "m",
                                       "--out", p],
    }
    for label, mk in outputs.items():
        for kind in OUT_SPECIALS + ["file-parent", "regular-dir-as-file"]:
            if kind in ("full", "null", "link-full") and not IS_ROOT:
                continue
            def setup(work, kind=kind):
                if kind == "file-parent":
                    (work / "plain").write_text("unrelated\n")
                elif kind == "regular-dir-as-file":
                    (work / "sp").mkdir()
                    (work / "sp" / "keep.txt").write_text("unrelated\n")
                else:
                    make_special(work, "sp", kind)
                (work / "m").mkdir()
                for i in range(6):
                    write_png(work / "m" / f"frame_{i:04d}.png", 32, 24)
            path = "plain/sub" if kind == "file-parent" else "sp"
            guards = ["plain"] if kind == "file-parent" else (
                ["sp/keep.txt"] if kind == "regular-dir-as-file" else ["sp", "sp.target"])
            expect = "fail"
            if kind == "regular-dir-as-file" and label in ("query --out", "export --out",
                                                          "render-path --out", "study --out",
                                                          "run runs_dir", "study merge --out"):
                continue  # an existing folder is a valid output folder there (see below)
            case(f"{label} -> {kind}", mk(path), expect=expect, names=[path.split("/")[0]],
                 setup=setup, guards=guards, timeout=60)

    # --- same input and output; output over an unrelated regular file is allowed but whole
    case("scene convert in == out", ["scene", "convert", "s.ply", "s.ply"], expect="ok",
         setup=lambda w: shutil.copy(scene, w / "s.ply"),
         check=lambda w, r: None if scene_ok(ctx, w / "s.ply") else ("DESTROYED",
                                                                     "s.ply unreadable"))
    case("scene convert out.spz by name writes SPZ", ["scene", "convert", scene, "o.spz"],
         expect="ok", check=lambda w, r: None if (w / "o.spz").read_bytes()[:2] == b"\x1f\x8b"
         else ("EXIT0", "o.spz is not gzip (SPZ)"))
    case("scene convert unknown ext", ["scene", "convert", scene, "o.xyz"], names=["o.xyz"],
         outs=["o.xyz"])
    case("scene convert --format bogus", ["scene", "convert", scene, "o.ply", "--format", "x"],
         names=["format"], outs=["o.ply"])
    case("scene convert into missing dir", ["scene", "convert", scene, "no/such/o.ply"],
         names=["no/such"], outs=["no"])
    case("scene demo --gaussians 0", ["scene", "demo", "--out", "d.ply", "--gaussians", "0"],
         names=["gaussians"], outs=["d.ply"])
    case("scene demo --gaussians 1e12", ["scene", "demo", "--out", "d.ply", "--gaussians",
                                         "1000000000000"], names=["gaussians"], outs=["d.ply"])
    case("scene demo --gaussians -1", ["scene", "demo", "--out", "d.ply", "--gaussians", "-1"],
         names=["gaussians"], outs=["d.ply"])
    case("render a 0-Gaussian scene", ["render", "--scene", "zero.ply", "--camera",
                                               cam, "--label", "1"], names=["zero.ply", "0"],
         setup=lambda w: (w / "zero.ply").write_bytes(ply_header(0).encode()))

    # --- config keys: NaN, inf, negative, zero, huge, wrong types (run --check)
    F = ["nan", "inf", "-inf", '"abc"', "true", "[1]"]
    I = ["-1", "1.5", '"abc"', "99999999999999999999999", "nan"]
    keys = {
        # key: (bad values beyond the generic ones, huge values)
        "seed": ([], []),
        "max_memory_gb": (["0", "-1"], []),
        "camera.width": (["0"], ["1000000"]),
        "camera.height": (["0"], ["1000000"]),
        "camera.fov_x": (["0", "-10", "180", "1e300"], []),
        "camera.fx": (["0", "-1", "1e300"], []),
        "camera.fy": (["0", "-1"], []),
        "camera.cx": (["1e300"], []),
        "camera.cy": (["-1e300"], []),
        "camera.target_ratio": (["0", "-0.1", "1.5"], []),
        "trajectory.centres_per_window": (["0"], ["1000000000"]),
        "trajectory.sigma": (["0", "-1"], []),
        "optimiser.iterations": (["0"], ["1000000000000"]),
        "optimiser.samples_per_window": (["0"], ["100000000"]),
        "optimiser.learning_rate": (["0", "-1", "1e30"], []),
        "optimiser.beta1": (["1", "-0.5", "2"], []),
        "optimiser.beta2": (["1.5", "-1"], []),
        "optimiser.epsilon": (["0", "-1"], []),
        "optimiser.position_unit": (["0", "-1"], []),
        "optimiser.time_limit_s": (["0", "-1"], []),
        "optimiser.path_samples": (["0"], ["1000000000"]),
        "start.jitter": (["-1"], []),
        "start.elevation": (["1e300"], []),
        "start.spread": (["-1"], []),
        "start.restarts": (["0"], ["10000000"]),
        "output.frames": (["0"], ["1000000000"]),
        "output.fps": (["0", "-30", "1e-300", "0.001"], ["1000000000"]),
        "output.seconds": (["0", "-1"], ["1000000000000"]),
        "output.width": (["0"], ["1000000"]),
        "output.height": (["0"], ["1000000"]),
        "output.trajectory_samples": (["0"], ["10000000000"]),
        "output.metric_samples": (["0"], ["10000000000"]),
        "output.ldj_samples": ([], ["10000000000"]),
        "costs.tce.weight": (["-1"], []),
        "costs.tre.weight": (["-1"], []),
        "costs.upright.weight": (["-1"], []),
        "costs.prior.alpha0": (["-1"], []),
        "costs.prior.gamma": (["-1", "2"], []),
        "costs.prior.radius": (["0", "-1"], []),
        "costs.clearance.weight": (["-1"], []),
        "costs.clearance.margin": (["-1"], []),
        "costs.clearance.sigma": (["0", "-1"], []),
        "costs.clearance.min_opacity": (["-1", "2"], []),
        "costs.motion.weight": (["-1"], []),
        "costs.motion.max_speed": (["0", "-1"], []),
        "costs.motion.max_acceleration": (["-1"], []),
        "costs.motion.max_angular_speed": (["-1"], []),
        "costs.visibility.weight": (["-1"], []),
        "costs.visibility.tolerance": (["-1", "2"], []),
        "approximations.stop_transmittance": (["-1", "2"], []),
        "approximations.min_opacity": (["-1", "2"], []),
        "sgld.iterations": ([], ["1000000000000"]),
        "sgld.step_size": (["-1"], []),
        "sgld.temperature": (["-1"], []),
        "sgld.thin": (["0"], []),
        "pose.query": (["99"], []),
        "pose.optimiser.iterations": (["0"], ["1000000000000"]),
        "pose.optimiser.lr_rotation": (["-1"], []),
        "pose.optimiser.lr_position": (["-1"], []),
        "targets.selection.top_fraction": (["0", "-1", "2"], []),
        "targets.selection.floor": (["1", "-1"], []),
        "targets.temperature": (["0", "-1"], []),
        "study.seeds": (["0"], ["1000000000"]),
        "study.evaluation.width": (["0"], ["1000000"]),
        "study.evaluation.samples": (["0"], ["10000000000"]),
        "scene.demo.gaussians": (["0"], ["10000000000"]),
        "scene.up": (["[0,0,0]", "[nan,0,1]", "[1,2]"], []),
    }
    int_like = ("width", "height", "iterations", "samples", "frames", "restarts", "seeds",
                "centres", "gaussians", "thin", "query", "seed")
    for key, (bad, huge) in keys.items():
        last = key.split(".")[-1]
        generic = I if any(w in last for w in int_like) else F
        if key == "scene.up":
            generic = ['"abc"']
        # `run` does not read [sgld], [pose] or [study]: only their types are checked there
        unused = key.split(".")[0] in ("sgld", "pose", "study")
        for v in dict.fromkeys(generic + bad):
            case(f"run --check {key}={v}", ["run", small, "--check", "--set", f"{key}={v}"],
                 names=[key.split(".")[-1]], timeout=20,
                 expect="any" if unused and v in bad else "fail")
        for v in huge:
            case(f"run --check {key}={v} (huge)", ["run", small, "--check", "--set",
                                                   f"{key}={v}"],
                 expect="any" if unused else "refuse_or_warn", names=[last], timeout=20)
    # ... so they are tried where they are read
    for kv, expect in [("pose.optimiser.iterations=0", "fail"),
                       ("pose.optimiser.lr_rotation=nan", "fail"),
                       ("sgld.iterations=1000000000000", "refuse_or_warn"),
                       ("sgld.step_size=-1", "fail"), ("sgld.thin=0", "fail")]:
        case(f"pose --sgld 2 --set {kv}", ["pose", small, "--quiet", "--sgld", "2", "--set", kv],
             expect=expect, names=[kv.split("=")[0].split(".")[-1]], timeout=30)
    for kv, expect in [("study.seeds=1000000000", "refuse_or_warn"),
                       ("study.evaluation.width=1000000", "refuse_or_warn"),
                       ("study.evaluation.samples=10000000000", "refuse_or_warn"),
                       ("study.evaluation.samples=0", "fail"), ("study.seeds=0", "fail")]:
        case(f"study --dry-run --set {kv}", ["study", small, "--dry-run", "--vary",
                                             "optimiser.iterations=1,2", "--set", kv],
             expect=expect, names=[kv.split("=")[0].split(".")[-1]], timeout=20)
    # a few not only checked but run: the check must catch what the run would trip on
    for kv in ["optimiser.learning_rate=1e30", "output.seconds=1e12", "output.fps=1e9",
               "optimiser.iterations=1000000000000", "start.restarts=10000000",
               "optimiser.path_samples=1000000000", "camera.fx=1e-30", "output.frames=1",
               "output.width=1", "output.height=1", "camera.width=1", "costs.tce.weight=1e308",
               "trajectory.centres_per_window=1000000"]:
        k, v = kv.split("=")
        case(f"run {kv}", ["run", small, "--quiet", "--set", kv,
                           "--set", "optimiser.time_limit_s=20", "--set",
                           'output.runs_dir="{W}/runs"'],
             expect="refuse_or_warn" if kv.split("=")[1] in (
                 "1e12", "1e9", "1000000000000", "10000000", "1000000000", "1000000")
             else ("fail" if kv == "camera.fx=1e-30" else "any"),
             names=[k.split(".")[-1]], timeout=90, check=lambda w, r: nonfinite_check(w, r))
    # malformed config files
    for label, text in [
        ("empty", ""), ("not toml", "name = [\n"), ("no queries", "name='x'\n[scene]\n"
                                                    "demo={gaussians=1000,seed=1}\n"),
        ("binary", "\0\1\2\3"), ("deep nesting", "a = " + "[" * 100000 + "]" * 100000 + "\n"),
        ("huge string", 'name = "' + "x" * (20 * 2**20) + '"\n'),
        ("unknown table", (Path(small).read_text() + "\n[bogus]\nx=1\n")),
        ("scene both path and demo", Path(small).read_text().replace(
            "[scene]\n", f'[scene]\npath = "{scene}"\n')),
        ("query text empty", Path(small).read_text().replace('"red mug"', '""')),
        ("query unknown label", Path(small).read_text().replace('"red mug"', '"unicorn"')),
        ("scene path missing", Path(small).read_text().replace(
            "demo = { gaussians = 5000, seed = 7 }", 'path = "missing.ply"')),
        ("runs_dir is a file", Path(small).read_text().replace(str(ctx.fx / "runs"),
                                                               "afile")),
    ]:
        def setup(work, text=text):
            (work / "c.toml").write_text(text)
            (work / "afile").write_text("unrelated\n")
        names = {"query text empty": ["queries.0.text"], "query unknown label": ["unicorn"],
                 "scene path missing": ["missing.ply"], "runs_dir is a file": ["afile"]
                 }.get(label, ["c.toml"])
        for cmd in (["run", "c.toml", "--check"], ["pose", "c.toml"],
                    ["study", "c.toml", "--dry-run"], ["query", "--config", "c.toml"]):
            if label in ("huge string", "deep nesting") and cmd[0] != "run":
                continue
            if label == "runs_dir is a file" and cmd[0] == "query":
                continue  # query writes no run folder
            case(f"{cmd[0]} config {label}", cmd, names=names, setup=setup, timeout=20,
                 guards=["afile"])
    # --set syntax
    for s in ["=1", "noequals", "optimiser.iterations=", "a..b=1", ".=1",
              "optimiser=5", "queries=[]", "camera.width=1 2"]:
        case(f"run --set {s!r}", ["run", small, "--check", "--set", s],
             names=["--set", "queries"])

    # --- render
    R = ["render", "--scene", scene, "--camera", cam, "--label", "1"]
    for flag, vals in {"--width": ["0", "1000000000", "-1", "nan"],
                       "--height": ["0", "1000000000"],
                       "--target-ratio": ["nan", "0", "-1", "2", "inf"],
                       "--repeats": ["0", "1000000000"],
                       "--label": ["unicorn", "99999"], "--backend": ["bogus"],
                       "--dtype": ["f16"]}.items():
        for v in vals:
            argv = R + [flag, v] + (["--grad"] if flag in ("--target-ratio", "--repeats")
                                    else [])
            huge = v == "1000000000"
            case(f"render {flag} {v}", argv, expect="refuse_or_warn" if huge else "fail",
                 names=[flag.strip("-"), flag], timeout=20)
    for label, camj in camera_variants():
        def setup(work, camj=camj):
            (work / "c.json").write_text(camj)
        case(f"render camera {label}", ["render", "--scene", scene, "--camera", "c.json",
                                        "--label", "1"], names=["c.json"], setup=setup)
    for label, data in npy_variants():
        def setup(work, data=data):
            (work / "m.npy").write_bytes(data)
        case(f"render --mask {label}", ["render", "--scene", scene, "--camera", cam,
                                        "--mask", "m.npy"], names=["m.npy"], setup=setup)

    # --- query
    Q = ["query", "--scene", scene, "--out", "q", "--width", "32", "--height", "24"]
    for extra, names in [
        (["--query", "red mug", "--width", "1000000", "--height", "1000000"], ["width"]),
        (["--query", "red mug", "--width", "0"], ["width"]),
        (["--box", "nan,0,0,1,1,1", "--query", "x"], ["box"]),
        (["--box", "1,1,1,0,0,0", "--query", "x"], ["box"]),
        (["--box", "1,2,3", "--query", "x"], ["box"]),
        (["--sphere", "0,0,0,-1", "--query", "x"], ["sphere"]),
        (["--sphere", "0,0,0,inf", "--query", "x"], ["sphere"]),
        (["--query", "red mug", "--top-fraction", "0"], ["top-fraction"]),
        (["--query", "red mug", "--top-fraction", "nan"], ["top-fraction"]),
        (["--query", "red mug", "--floor", "1"], ["floor"]),
        (["--query", "red mug", "--elevation", "nan"], ["elevation"]),
        (["--query", "red mug", "--elevation", "1e300"], ["elevation"]),
        (["--query", "red mug", "--up", "0,0,0"], ["up"]),
        (["--query", "red mug", "--up", "nan,0,1"], ["up"]),
        (["--query", "red mug", "--temperature", "0", "--source", "features"],
         ["temperature", "features"]),
        (["--query", "unicorn"], ["unicorn"]),
        (["--query", "red mug", "--source", "custom.nonexistent"], ["nonexistent"]),
        (["--query", "red mug", "--synonym", "noequals"], ["synonym"]),
        (["--query", "red mug", "--set", "targets.selection.floor=nan"], ["floor"]),
        (["--query", "mug", "--latents", "nope.npy", "--checkpoint", "nope.pth"],
         ["nope", "--phrases"]),
    ]:
        case(f"query {' '.join(extra)}", Q + extra, names=names, outs=["q/query.png"])

    # --- pose
    P = ["pose", small, "--quiet"]
    for extra, names, expect in [
        (["--restarts", "0"], ["restarts"], "fail"),
        (["--restarts", "100000000"], ["restarts"], "refuse_or_warn"),
        (["--sgld", "1000000000"], ["sgld"], "refuse_or_warn"),
        (["--ablation", "bogus"], ["ablation"], "fail"),
        (["--set", "pose.query=7"], ["query"], "fail"),
        (["--max-memory", "nan"], ["max-memory"], "fail"),
        (["--max-memory", "-1"], ["max-memory"], "fail"),
        (["--max-memory", "0.000001"], ["memory"], "fail"),
        (["--set", "pose.optimiser.iterations=1000000000000"], ["iterations"],
         "refuse_or_warn"),
    ]:
        case(f"pose {' '.join(extra)}", P + extra, expect=expect, names=names, timeout=30)

    # --- study
    S = ["study", small, "--quiet"]
    for extra, names, expect in [
        (["--seeds", "1000000000", "--dry-run"], ["seeds"], "refuse_or_warn"),
        (["--seeds", "0", "--dry-run"], ["seeds"], "fail"),
        (["--vary", "optimiser.iterations=" + ",".join(str(i) for i in range(1, 1001)),
          "--vary", "seed=" + ",".join(str(i) for i in range(1000)), "--grid", "--dry-run"],
         ["runs", "variants"], "refuse_or_warn"),
        (["--vary", "bogus.key=1,2", "--dry-run"], ["bogus"], "fail"),
        (["--vary", "optimiser.iterations", "--dry-run"], ["vary"], "fail"),
        (["--vary", "optimiser.iterations=nan,1", "--dry-run"], ["iterations"], "fail"),
        (["--shard", "0/0", "--dry-run"], ["shard"], "fail"),
        (["--shard", "5/3", "--dry-run"], ["shard"], "fail"),
        (["--shard", "abc", "--dry-run"], ["shard"], "fail"),
        (["--preset", "bogus", "--dry-run"], ["preset"], "fail"),
        (["--set", "optimiser.iterations=nan", "--dry-run"], ["iterations"], "fail"),
    ]:
        case(f"study {' '.join(extra)[:80]}", S + extra, expect=expect, names=names,
             timeout=20)
    for label, setup, args in [
        ("empty dirs", lambda w: ((w / "a").mkdir(), (w / "b").mkdir()), ["a", "b"]),
        ("missing", None, ["nope1", "nope2"]),
        ("same twice", lambda w: (w / "a").mkdir(), ["a", "a"]),
        ("garbage files", lambda w: ((w / "a").mkdir(), (w / "a" / "study.json").write_text(
            "{bad"), (w / "a" / "results.csv").write_text("x\n1,2,3\n")), ["a"]),
    ]:
        case(f"study merge {label}", ["study", "merge", "--out", "m"] + args, setup=setup,
             names=[args[0]], outs=["m"])

    # --- bench (bad sizes must be refused quickly)
    for extra, names in [
        (["render", "--threads", "100000", "--sizes", "1000", "--resolutions", "16"],
         ["threads"]),
        (["render", "--sizes", "0", "--resolutions", "16"], ["sizes", "gaussians"]),
        (["render", "--sizes", "1000000000000", "--resolutions", "16"], ["sizes", "gaussians"]),
        (["render", "--sizes", "1000", "--resolutions", "1000000"], ["resolutions"]),
        (["render", "--sizes", "1000", "--resolutions", "16", "--repeats", "1000000000"],
         ["repeats"]),
        (["render", "--sizes", "1000", "--resolutions", "16", "--fov", "nan"], ["fov"]),
        (["render", "--scene", "nope.ply", "--no-demo"], ["nope.ply"]),
        (["scale", "--config", small, "--sizes", "1000000000000", "--iterations", "1"],
         ["sizes", "gaussians"]),
        (["scale", "--config", "nope.toml"], ["nope.toml"]),
        (["scale", "--config", small, "--sizes", "1000", "--iterations", "1000000000000"],
         ["iterations"]),
        (["first-try", "nope.toml"], ["nope.toml"]),
        (["frames", "--no-scene", "--gaussians", "1000", "--sizes", "100000x100000"],
         ["sizes"]),
        (["frames", "--no-scene", "--gaussians", "1000", "--fps", "nan"], ["fps"]),
        (["frames", "--no-scene", "--gaussians", "1000", "--seconds", "1e12"], ["seconds"]),
        (["frames", "--no-scene", "--gaussians", "1000", "--schedule", "pipelined:0"],
         ["schedule"]),
    ]:
        expect = "refuse_or_warn" if any("100000" in e or "1e12" in e for e in extra) \
            else "fail"
        case(f"bench {' '.join(extra)}", ["bench"] + extra, expect=expect, names=names,
             timeout=30)

    # --- encode-text
    for label, data in [("garbage", b"not weights"), ("empty", b""),
                        ("fake safetensors", struct.pack("<Q", 2**40) + b"{"),
                        ("safetensors header lie", struct.pack("<Q", 30) +
                         b'{"w":{"dtype":"F32","shape":[100000000,100000000],'
                         b'"data_offsets":[0,4]}}' + b"\0" * 4)]:
        def setup(work, data=data):
            (work / "enc.safetensors").write_bytes(data)
        case(f"encode-text {label}", ["encode-text", "--text-encoder", "enc.safetensors",
                                      "--out", "t.json", "mug"], names=["enc.safetensors"],
             setup=setup, outs=["t.json"])

    # --- lift-masks
    L = ["scene", "lift-masks", "--scene", scene, "--cameras",
         f"{run}/exports/inria/cameras.json", "--out", "l.json"]
    case("lift-masks missing masks dir", L + ["--masks", "nope"], names=["nope"],
         outs=["l.json"])
    case("lift-masks empty masks dir", L + ["--masks", "m"], names=["m", "mask"],
         setup=lambda w: (w / "m").mkdir(), outs=["l.json"])
    case("lift-masks garbage png", L + ["--masks", "m"], names=["frame_0000", "png"],
         setup=lambda w: ((w / "m").mkdir(), (w / "m" / "frame_0000.png").write_bytes(
             b"\x89PNG\r\n\x1a\ngarbage")), outs=["l.json"])
    case("lift-masks png wrong size", L + ["--masks", "m"], names=["frame_0000", "size"],
         setup=lambda w: ((w / "m").mkdir(), write_png(w / "m" / "frame_0000.png", 7, 5)),
         outs=["l.json"])
    case("lift-masks png huge dims", L + ["--masks", "m"], names=["frame_0000"],
         setup=lambda w: ((w / "m").mkdir(), write_png(w / "m" / "frame_0000.png", 100000,
                                                        100000, lie=True)), outs=["l.json"])
    for flag, v in [("--min-share", "0"), ("--min-share", "nan"), ("--min-share", "2"),
                    ("--neighbours", "1000000000")]:
        case(f"lift-masks {flag} {v}", L + ["--masks", "m", flag, v], names=[flag[2:]],
             setup=lambda w: (w / "m").mkdir(), outs=["l.json"])

    # --- export and render-path: malformed trajectory and camera files
    for label, text in trajectory_variants(Path(traj)):
        def setup(work, text=text):
            (work / "t.json").write_text(text)
        case(f"export trajectory {label}", ["export", "t.json", "--format", "colmap", "--out",
                                            "e"], names=["t.json"], setup=setup, outs=["e"])
        case(f"render-path trajectory {label}", ["render-path", scene, "t.json", "--out", "rp",
                                                 "--quiet", "--seconds", "0.2"],
             names=["t.json"], setup=setup, outs=["rp"], timeout=30)
    for fmt, fname, variants in camera_file_variants(Path(run)):
        for label, text in variants:
            def setup(work, text=text, fname=fname):
                (work / fname).write_text(text)
            case(f"render-path {fmt} {label}", ["render-path", scene, fname, "--out", "rp",
                                                "--quiet"], names=[fname], setup=setup,
                 outs=["rp"], timeout=30)
    E = ["export", run, "--format", "nerfstudio", "--out", "e"]
    for flag, v in [("--fps", "1e9"), ("--fps", "0"), ("--fps", "nan"), ("--seconds", "1e12"),
                    ("--seconds", "-1"), ("--width", "1000000000"), ("--width", "0"),
                    ("--format", "bogus")]:
        case(f"export {flag} {v}", E + [flag, v], names=[flag[2:]], outs=["e"])
    RP = ["render-path", scene, traj, "--out", "rp", "--quiet"]
    for flag, v in [("--fps", "1e9"), ("--fps", "0"), ("--fps", "nan"), ("--seconds", "1e12"),
                    ("--seconds", "0"), ("--width", "1000000000"), ("--height", "0"),
                    ("--width", "nan"), ("--mask-overlay", "tint"), ("--rasterizer", "bogus"),
                    ("--set", "camera.width=5")]:
        case(f"render-path {flag} {v}", RP + [flag, v], names=[flag[2:]], outs=["rp"],
             timeout=30)
    case("render-path config with --set nan", ["render-path", small, traj, "--out", "rp",
                                               "--set", "output.fps=nan", "--quiet"],
         names=["fps"], outs=["rp"], timeout=30)
    case("render-path config of another scene", ["render-path", small, traj, "--out", "rp",
                                                 "--quiet", "--set",
                                                 "scene.demo.gaussians=3000"],
         names=["scene", "gaussians", "trajectory"], outs=["rp"], timeout=30)

    # --- re-running into an existing output folder; concurrent writers
    case("render-path twice, fewer frames", [], expect="ok", runner=rerun_render_path(ctx),
         timeout=90)
    case("render-path twice concurrently", [], expect="ok",
         runner=concurrent(ctx, ["render-path", scene, traj, "--out", "rp", "--quiet",
                                 "--seconds", "1", "--width", "32"], "rp"), timeout=120)
    case("export twice concurrently", [], expect="ok",
         runner=concurrent(ctx, ["export", run, "--format", "colmap", "--out", "e"], "e"),
         timeout=60)
    case("query twice concurrently", [], expect="ok",
         runner=concurrent(ctx, ["query", "--scene", scene, "--query", "red mug", "--out", "q",
                                 "--width", "64", "--height", "48"], "q"), timeout=60)
    case("run twice concurrently, same runs_dir", [], expect="ok",
         runner=concurrent(ctx, ["run", small, "--quiet", "--set", 'output.runs_dir="{W}/runs"'],
                           "runs"), timeout=120)
    case("study twice into one --out", [], expect="ok",
         runner=concurrent(ctx, ["study", small, "--quiet", "--out", "st", "--vary",
                                 "optimiser.iterations=1,2"], "st"), timeout=180)

    # --- report on malformed run folders
    for label, mutate in report_variants(scene):
        def setup(work, mutate=mutate):
            shutil.copytree(run, work / "run")
            mutate(work / "run")
        case(f"report {label}", ["report", "run"], names=["run"], setup=setup, timeout=30,
             check=report_kept(Path(run) / "report.html"))
    case("report --scene another scene", ["report", "run", "--scene", "other.ply"],
         names=["other.ply", "scene"],
         setup=lambda w: (shutil.copytree(run, w / "run"),
                          shutil.copy(ctx.fx / "hand.ply", w / "other.ply")))
    case("report on a non-run folder", ["report", "d"], names=["d"],
         setup=lambda w: (w / "d").mkdir())

    # --- resume of missing, foreign and damaged run folders
    for label, mutate in [
        ("checkpoint garbage", lambda d: (d / "checkpoint.json").write_text("{")),
        ("checkpoint missing", lambda d: (d / "checkpoint.json").unlink()),
        ("checkpoint NaN weights", lambda d: (d / "checkpoint.json").write_text(
            re.sub(r"(\"weights\":\s*\[\s*\[\s*)-?[0-9.e-]+", r"\1NaN",
                   (d / "checkpoint.json").read_text(), count=1))),
        ("checkpoint is a fifo", lambda d: ((d / "checkpoint.json").unlink(),
                                            os.mkfifo(d / "checkpoint.json"))),
        ("config missing", lambda d: (d / "config.toml").unlink()),
        ("config of another shape", lambda d: (d / "config.toml").write_text(
            re.sub(r"centres_per_window = \d+", "centres_per_window = 5",
                   (d / "config.toml").read_text()))),
        ("config iterations nan", lambda d: (d / "config.toml").write_text(
            re.sub(r"iterations = \d+", "iterations = nan", (d / "config.toml").read_text(),
                   count=1))),
    ]:
        def setup(work, mutate=mutate):
            shutil.copytree(ctx.fx / "interrupted", work / "run")
            mutate(work / "run")
        case(f"run --resume {label}", ["run", "--resume", "run", "--quiet"],
             names=["checkpoint", "config", "centres", "iterations"], setup=setup, timeout=60)
    case("run --resume a finished run", ["run", "--resume", "run"], names=["finished"],
         setup=lambda w: shutil.copytree(run, w / "run"))
    case("run --resume missing folder", ["run", "--resume", "nope"], names=["nope"])
    case("run --resume a file", ["run", "--resume", "f"], names=["f"],
         setup=lambda w: (w / "f").write_text("x"), guards=["f"])
    case("run --resume <- fifo", ["run", "--resume", "sp"], names=["sp"],
         setup=lambda w: make_special(w, "sp", "fifo"), guards=["sp"])

    # --- signals during `run` and other long commands
    slow = f"{fx}/slow.toml"
    for sig, delay, twice in [(signal.SIGINT, 0.3, False), (signal.SIGINT, 2.0, False),
                              (signal.SIGTERM, 4.0, False), (signal.SIGINT, 9.0, False),
                              (signal.SIGTERM, 10.5, False), (signal.SIGINT, 9.5, True),
                              (signal.SIGINT, 11.5, True), (signal.SIGKILL, 3.0, False),
                              (signal.SIGKILL, 10.0, False)]:
        name = f"run {signal.Signals(sig).name} at {delay}s{' twice' if twice else ''}"
        case(name, ["run", slow, "--set", 'output.runs_dir="{W}/runs"'], expect="ok",
             runner=signalled(ctx, sig, delay, twice, resume=True), timeout=120)
    frames_phase = ["--set", "optimiser.iterations=30", "--set", "output.frames=900"]
    for sig, delay, twice in [(signal.SIGINT, 3.0, False), (signal.SIGTERM, 4.0, False),
                              (signal.SIGINT, 3.5, True)]:
        name = (f"run (frames phase) {signal.Signals(sig).name} at {delay}s"
                f"{' twice' if twice else ''}")
        case(name, ["run", slow, "--set", 'output.runs_dir="{W}/runs"'] + frames_phase,
             expect="ok", runner=signalled(ctx, sig, delay, twice, resume=True), timeout=120)
    for label, argv, delay in [
        ("render-path", ["render-path", scene, traj, "--out", "rp", "--quiet", "--seconds", "20",
                         "--width", "320"], 2.0),
        ("study", ["study", slow, "--quiet", "--out", "st", "--set", "output.frames=6", "--vary",
                   "optimiser.iterations=2000,3000"], 3.0),
        ("bench render", ["bench", "render", "--sizes", "20000", "--resolutions", "64,128",
                          "--repeats", "20"], 2.0),
        ("bench scale", ["bench", "scale", "--config", small, "--sizes", "5000,10000",
                         "--iterations", "20", "--runs-dir", "bs"], 2.0),
        ("pose", ["pose", slow, "--quiet", "--restarts", "4", "--set",
                  "pose.optimiser.iterations=2000"], 2.0),
    ]:
        for sig in (signal.SIGINT, signal.SIGTERM):
            case(f"{label} {signal.Signals(sig).name} at {delay}s", argv, expect="ok",
                 runner=signalled(ctx, sig, delay, False, resume=False), timeout=60)

    # --- second round (issue 27, after the first fixes): degenerate scales, environment,
    # parser limits, the address-space limit
    for kv, names in [
        ("camera.fov_x=179.9999", ["fov_x", "working distance"]),
        ("camera.target_ratio=1e-300", ["target ratio", "working distance"]),
        ("camera.target_ratio=1e-9", ["target ratio", "working distance"]),
        ("queries.0.target_ratio=1e-300", ["target ratio", "working distance"]),
        ("costs.clearance.margin=1e300", ["margin"]),
        ("costs.motion.max_speed=1e-300", ["max_speed"]),
        ("start.spread=1e-300", ["spread"]),
        ("camera.width=3000", ["ulimit"]),
        ('name="../../escaped"', ["name"]),
        ("optimiser.beta1=1", ["beta1"]),
        ("optimiser.learning_rate=0", ["learning_rate"]),
    ]:
        expect = "any" if kv.startswith(("costs.", "start.")) else "fail"
        extra = ["--set", "camera.height=3000"] if kv == "camera.width=3000" else []
        case(f"run --check {kv} (round 2)", ["run", small, "--check", "--set", kv] + extra,
             names=names, expect=expect, timeout=60)
    case("run --check costs.clearance.margin=1e-12 (round 2)",
         ["run", small, "--check", "--set", "costs.clearance.margin=1e-12"], expect="ok",
         timeout=60)

    def deep_toml(work):
        (work / "deep.toml").write_text("a = " + "[" * 100000 + "]" * 100000 + "\n")
    case("run --check config nested 100000 deep", ["run", "deep.toml", "--check"],
         names=["deep.toml", "line 1"], setup=deep_toml)

    def many_queries(work):
        text = (ctx.fx / "small.toml").read_text()
        at = text.index("[camera]")
        (work / "many.toml").write_text(
            text[:at] + '\n[[queries]]\ntext = "red mug"\n' * 20000 + text[at:])
    case("run --check 20000 queries", ["run", "many.toml", "--check"], expect="refuse_or_warn",
         names=["windows"], setup=many_queries, timeout=120)

    def long_line(work):
        text = (ctx.fx / "small.toml").read_text()
        (work / "long.toml").write_text("# " + "x" * 20_000_000 + "\n" + text)
    case("run --check config with a 20 MB comment line", ["run", "long.toml", "--check"],
         expect="any", names=["long.toml"], setup=long_line, timeout=60)

    for value, names in [("100000", ["RAYON_NUM_THREADS"]), ("four", ["RAYON_NUM_THREADS"]),
                         ("-1", ["RAYON_NUM_THREADS"])]:
        case(f"scene info with RAYON_NUM_THREADS={value}", ["scene", "info", scene],
             names=names, runner=with_env(ctx, {"RAYON_NUM_THREADS": value}), timeout=30)
    case("render with RAYON_NUM_THREADS=1", ["render", "--scene", scene, "--camera", cam,
                                            "--label", "1", "--width", "32", "--out", "r"],
         expect="ok", runner=with_env(ctx, {"RAYON_NUM_THREADS": "1"}), timeout=60)

    # --- third round (issue 39): sizes read from content, values that pass `--check` and fail
    # later, messages that name the wrong thing, lenient JSON
    # lift-masks: masks whose every pixel is its own colour (a label each), at rescales of the
    # 32 × 24 cameras
    def rainbow_masks(w, h, n=2):
        def setup(work):
            (work / "m").mkdir()
            for i in range(n):
                write_png(work / "m" / f"frame_{i:04d}.png", w, h, first_colour=1 + i * w * h)
        return setup
    for w, h in [(400, 300), (128, 96)]:
        case(f"lift-masks 2 masks {w}x{h}, every pixel its own colour", L + ["--masks", "m"],
             names=["labels"], setup=rainbow_masks(w, h), outs=["l.json"], timeout=30)

    # SOG: means images of 16383² texels for 100 Gaussians (refused from the WebP header),
    # beside a control whose images fit the count
    fits = {n: (10, 10) for n in ("means_l.webp", "means_u.webp", "quats.webp", "scales.webp",
                                  "sh0.webp")}
    for label, sizes, expect in [
        ("images fit (control)", fits, "ok"),
        ("means 16383x16383", {**fits, "means_l.webp": (16383, 16383),
                               "means_u.webp": (16383, 16383)}, "fail"),
        ("quats 16383x16383", {**fits, "quats.webp": (16383, 16383)}, "fail"),
    ]:
        case(f"scene info SOG count 100, {label}", ["scene", "info", "s.sog"], expect=expect,
             names=["s.sog"], setup=lambda w, sizes=sizes: sog_of(100, sizes)(w / "s.sog"),
             check=None if expect == "ok" else names_all("s.sog", label.split()[0]),
             timeout=20)

    # a run checkpoint that cannot be right (resumed without a word before)
    def checkpoint_with(**changes):
        def setup(work):
            shutil.copytree(ctx.fx / "interrupted", work / "run")
            ck = work / "run" / "checkpoint.json"
            ck.write_text(json.dumps({**json.loads(ck.read_text()), **changes}, indent=1))
        return setup
    for field, value in [("steps_done", 10**18), ("restart", 7), ("best_restart", 7),
                         ("elapsed_s", -5.0), ("elapsed_s", float("nan"))]:
        case(f"run --resume checkpoint {field}={value}", ["run", "--resume", "run", "--quiet"],
             names=[field], setup=checkpoint_with(**{field: value}),
             check=names_all("checkpoint.json", field), timeout=60)

    # targets.lifted.up (the lifted source; the text encoder only has to exist, the up is
    # checked before it is read: the control proves the case gets that far)
    lifted = ["run", small, "--check", "--set", 'targets.source="lifted"',
              "--set", 'targets.text_encoder="{W}/enc.safetensors"']
    for v, key in [("[0,0,0]", "targets.lifted.up"), ("[nan,0,1]", "targets.lifted.up"),
                   ("[0,0,1e-300]", "targets.lifted.up"), ("[0,0,1]", "text_encoder")]:
        case(f"run --check lifted targets.lifted.up={v}", lifted + ["--set",
                                                                   f"targets.lifted.up={v}"],
             names=[key], check=names_all(key),
             setup=lambda w: (w / "enc.safetensors").write_text("not weights\n"))

    # a nerfstudio transforms.json of camera_angle_x 4 rad (> π) wherever cameras are read
    def transforms(angle):
        def setup(work):
            (work / "t").mkdir()
            (work / "t" / "transforms.json").write_text(transforms_from_inria(run, angle))
            (work / "c.toml").write_text(Path(small).read_text().replace(
                "demo = { gaussians = 5000, seed = 7 }", f'path = "{scene}"'))
        return setup
    tj = "t/transforms.json"
    for label, argv in [
        ("render-path", ["render-path", scene, tj, "--out", "rp", "--quiet", "--no-video"]),
        ("lift-masks --cameras", ["scene", "lift-masks", "--scene", scene, "--cameras", tj,
                                  "--masks", "m", "--out", "l.json"]),
        ("scene.cameras", ["run", "c.toml", "--check", "--set",
                           'scene.cameras="{W}/t/transforms.json"']),
        ("targets.lifted.cameras", lifted + ["--set",
                                             'targets.lifted.cameras="{W}/t/transforms.json"']),
    ]:
        case(f"{label} transforms.json camera_angle_x=4.0", argv, names=["camera_angle_x"],
             setup=transforms(4.0), check=names_all("transforms.json", "camera_angle_x"),
             outs=["rp", "l.json"], timeout=30)
    case("render-path transforms.json camera_angle_x=1.0 (control)",
         ["render-path", scene, tj, "--out", "rp", "--quiet", "--no-video"], expect="ok",
         setup=transforms(1.0), timeout=30)

    # query --text-encoder of a missing file: the message names the flag given, not another
    for extra in [[], ["--source", "lifted"], ["--phrases", "p.json"],
                  ["--source", "custom.feature3dgs"]]:
        case(f"query --text-encoder missing {' '.join(extra)}".rstrip(),
             ["query", "--scene", scene, "--query", "mug", "--out", "q", "--text-encoder",
              "nope.safetensors"] + extra, names=["--text-encoder"],
             check=names_all("--text-encoder", "nope.safetensors", unless=["--source-key"]),
             outs=["q"])


def report_kept(original):
    def check(work, r):
        p = work / "run" / "report.html"
        if r.rc != 0 and p.is_file() and p.read_bytes() != original.read_bytes():
            return ("HALF", "refused, but report.html was rewritten")
        return None
    return check


def scene_ok(ctx, path):
    r = subprocess.run([ctx.binary, "scene", "info", str(path)], capture_output=True)
    return r.returncode == 0


def nonfinite_check(work, r):
    """A run that exits 0/3 must not have written non-finite numbers."""
    if r.rc not in (0, 3):
        return None
    import re
    for p in Path(work).rglob("*"):
        if p.name in ("metrics.json", "history.csv") and p.is_file():
            t = p.read_text(errors="replace")
            # null is how an undefined metric (object never in view) is written: allowed
            if re.search(r"\b(nan|inf|infinity)\b", t, re.I):
                return ("EXIT0", f"{p.name} holds non-finite values (NaN/inf)")
    return None


def write_png(path, w, h, lie=False, first_colour=None):
    """A grey PNG of label 1; with `first_colour`, an RGB PNG whose every pixel is its own
    colour (first_colour, first_colour + 1, ... as 24-bit RGB)."""
    import zlib

    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))
    rgb = first_colour is not None
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 2 if rgb else 0, 0, 0, 0)
    if lie:
        raw = b""
    elif rgb:
        raw = b"".join(b"\0" + b"".join((first_colour + y * w + x).to_bytes(3, "big")
                                        for x in range(w)) for y in range(h))
    else:
        raw = b"".join(b"\0" + b"\1" * w for _ in range(h))
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw)) \
        + chunk(b"IEND", b"")
    Path(path).write_bytes(data)


def camera_variants():
    base = json.loads((REPO / "configs" / "cameras" / "demo_mug.json").read_text())
    out = [("empty", ""), ("not json", "{"), ("array", "[]"),
           ("deep nesting", "[" * 200000 + "]" * 200000)]
    for k, v in [("fx", 0), ("fx", -1), ("fx", "NaN"), ("fy", 1e308), ("width", 0),
                 ("width", 10**9), ("height", -1), ("width", 1.5), ("cx", "x"),
                 ("pose", [0, 0, 0]), ("pose", [0, 0, 0, 0, 0, 1e20]),
                 ("pose", ["NaN", 0, 0, 0, 0, 0]), ("world_to_camera", [[1, 0], [0, 1]])]:
        c = dict(base)
        c[k] = v
        txt = json.dumps(c).replace('"NaN"', "NaN")
        out.append((f"{k}={v}", txt))
    c = dict(base)
    del c["pose"]
    out.append(("no pose", json.dumps(c)))
    # strict JSON (issue 39): nothing after the object
    out.append(("trailing object", json.dumps(base) + ' {"fx": 1}'))
    out.append(("trailing text", json.dumps(base) + "\nnot json"))
    return out


def npy_variants():
    def npy(header, body):
        h = header.encode()
        h += b" " * ((64 - (10 + len(h) + 1) % 64) % 64) + b"\n"
        return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(h)) + h + body
    return [
        ("garbage", b"nonsense"),
        ("shape lie", npy("{'descr': '|u1', 'fortran_order': False, 'shape': (5000,), }",
                          b"\1" * 100)),
        ("shape huge", npy("{'descr': '|u1', 'fortran_order': False, 'shape': "
                           "(100000000000000,), }", b"\1" * 100)),
        ("wrong length", npy("{'descr': '|u1', 'fortran_order': False, 'shape': (7,), }",
                             b"\1" * 7)),
        ("complex dtype", npy("{'descr': '<c16', 'fortran_order': False, 'shape': (5000,), }",
                              b"\0" * 16 * 5000)),
        ("nan floats", npy("{'descr': '<f4', 'fortran_order': False, 'shape': (5000,), }",
                           struct.pack("<f", float("nan")) * 5000)),
        ("values 7", npy("{'descr': '|u1', 'fortran_order': False, 'shape': (5000,), }",
                         b"\7" * 5000)),
        ("header length lie", b"\x93NUMPY\x01\x00" + struct.pack("<H", 65535) + b"{"),
        ("2d", npy("{'descr': '|u1', 'fortran_order': False, 'shape': (5000, 2), }",
                   b"\1" * 10000)),
    ]


def trajectory_variants(path):
    t = json.loads(path.read_text())
    out = [("empty", ""), ("not json", "{"), ("deep nesting", "[" * 200000 + "]" * 200000)]

    def v(label, f):
        c = json.loads(json.dumps(t))
        f(c)
        out.append((label, json.dumps(c).replace('"NaN"', "NaN").replace('"INF"', "1e999")))
    v("missing weight row", lambda c: c["weights"].pop())
    v("extra weight row", lambda c: c["weights"].append([0] * 6))
    v("short weight row", lambda c: c["weights"][0].pop())
    v("weights 1e300", lambda c: c["weights"][0].__setitem__(3, 1e300))
    v("weight NaN", lambda c: c["weights"][0].__setitem__(0, "NaN"))
    v("weight inf", lambda c: c["weights"][0].__setitem__(0, "INF"))
    v("weight string", lambda c: c["weights"][0].__setitem__(0, "x"))
    v("fx 0", lambda c: c["intrinsics"].__setitem__("fx", 0))
    v("fx NaN", lambda c: c["intrinsics"].__setitem__("fx", "NaN"))
    v("output fx -1", lambda c: c["output_intrinsics"].__setitem__("fx", -1))
    v("width 0", lambda c: c["intrinsics"].__setitem__("width", 0))
    v("output width 1e9", lambda c: c["output_intrinsics"].__setitem__("width", 10**9))
    v("centres_per_window huge", lambda c: c["model"].__setitem__("centres_per_window", 10**12))
    v("windows huge", lambda c: c["model"].__setitem__("windows", 10**9))
    v("windows 0", lambda c: c["model"].__setitem__("windows", 0))
    v("kind bogus", lambda c: c["model"].__setitem__("kind", "bogus"))
    v("no model", lambda c: c.pop("model"))
    v("world_up zero", lambda c: c.__setitem__("world_up", [0, 0, 0]))
    v("windows list mismatch", lambda c: c["windows"].pop())
    v("window end < start", lambda c: c["windows"][0].__setitem__("end", -1))
    return out


def camera_file_variants(run):
    ns = json.loads((run / "exports/nerfstudio/camera_path.json").read_text())
    nv = []

    def n(label, f):
        c = json.loads(json.dumps(ns))
        f(c)
        nv.append((label, json.dumps(c).replace('"NaN"', "NaN")))
    n("no keyframes", lambda c: (c.__setitem__("keyframes", []), c.__setitem__("camera_path", [])
                                 if "camera_path" in c else None))
    n("matrix 15", lambda c: [k["matrix"].pop() for k in c.get("keyframes", [])]
      + [k["camera_to_world"].pop() for k in c.get("camera_path", [])
         if isinstance(k.get("camera_to_world"), list)])
    n("camera 1e20", lambda c: [k["camera_to_world"].__setitem__(3, 1e20)
                                for k in c.get("camera_path", [])
                                if isinstance(k.get("camera_to_world"), list)]
      + [k["matrix"].__setitem__(12, 1e20) for k in c.get("keyframes", [])])
    n("fov 0", lambda c: [k.__setitem__("fov", 0) for k in c.get("camera_path", [])
                          + c.get("keyframes", [])])
    n("fov NaN", lambda c: [k.__setitem__("fov", "NaN") for k in c.get("camera_path", [])
                            + c.get("keyframes", [])])
    n("render size huge", lambda c: (c.__setitem__("render_width", 10**9),
                                     c.__setitem__("render_height", 10**9)))
    n("seconds huge", lambda c: c.__setitem__("seconds", 1e15))
    n("fps 1e9", lambda c: c.__setitem__("fps", 1e9))
    n("fps 0", lambda c: c.__setitem__("fps", 0))
    n("aspect 0", lambda c: [k.__setitem__("aspect", 0) for k in c.get("camera_path", [])
                             + c.get("keyframes", [])])
    images = (run / "exports/colmap/images.txt").read_text()
    lines = images.splitlines()
    data_idx = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")]
    first = lines[data_idx[0]].split()
    cv = []

    def col(label, tokens):
        ls = list(lines)
        ls[data_idx[0]] = " ".join(tokens)
        cv.append((label, "\n".join(ls) + "\n"))
    col("zero quaternion", first[:1] + ["0", "0", "0", "0"] + first[5:])
    col("nan translation", first[:5] + ["nan"] + first[6:])
    col("short line", first[:4])
    col("text", ["a"] * 10)
    col("camera id missing", first[:8] + ["999"] + first[9:])
    cv.append(("empty", ""))
    cv.append(("comments only", "# nothing\n"))
    inria = json.loads((run / "exports/inria/cameras.json").read_text())
    iv = []

    def inr(label, f):
        c = json.loads(json.dumps(inria))
        f(c)
        iv.append((label, json.dumps(c).replace('"NaN"', "NaN")))
    inr("rotation scaled", lambda c: c[0].__setitem__("rotation", [[5, 0, 0], [0, 5, 0],
                                                                    [0, 0, 5]]))
    inr("rotation 2x2", lambda c: c[0].__setitem__("rotation", [[1, 0], [0, 1]]))
    inr("width 0", lambda c: c[0].__setitem__("width", 0))
    inr("width huge", lambda c: c[0].__setitem__("width", 10**9))
    inr("fx NaN", lambda c: c[0].__setitem__("fx", "NaN"))
    inr("position 1e20", lambda c: c[0].__setitem__("position", [1e20, 0, 0]))
    inr("empty list", lambda c: c.clear())
    ss = json.loads((run / "exports/supersplat/settings.json").read_text())
    sv = []

    def sup(label, f):
        c = json.loads(json.dumps(ss))
        f(c)
        sv.append((label, json.dumps(c).replace('"NaN"', "NaN")))
    tr = lambda c: c["animTracks"][0]
    sup("frameRate 0", lambda c: tr(c).__setitem__("frameRate", 0))
    sup("frameRate NaN", lambda c: tr(c).__setitem__("frameRate", "NaN"))
    sup("frameRate 1e9", lambda c: tr(c).__setitem__("frameRate", 1e9))
    sup("duration 1e12", lambda c: tr(c).__setitem__("duration", 1e12))
    sup("times decreasing", lambda c: tr(c)["keyframes"].__setitem__(
        "times", list(reversed(tr(c)["keyframes"]["times"]))))
    sup("times huge", lambda c: tr(c)["keyframes"]["times"].__setitem__(-1, 1e12))
    sup("fov short", lambda c: tr(c)["keyframes"]["values"]["fov"].pop())
    sup("position short", lambda c: tr(c)["keyframes"]["values"]["position"].pop())
    sup("no tracks", lambda c: c.__setitem__("animTracks", []))
    return [("nerfstudio", "camera_path.json", nv), ("colmap", "images.txt", cv),
            ("inria", "cameras.json", iv), ("supersplat", "settings.json", sv)]


def report_variants(scene):
    def w(name, text):
        return lambda d: (d / name).write_text(text)

    def rm(name):
        return lambda d: (d / name).unlink()

    def edit_metrics(f):
        def m(d):
            j = json.loads((d / "metrics.json").read_text())
            f(j)
            (d / "metrics.json").write_text(json.dumps(j).replace('"NaN"', "NaN"))
        return m
    return [
        ("metrics truncated", lambda d: (d / "metrics.json").write_text(
            (d / "metrics.json").read_text()[:200])),
        ("metrics empty", w("metrics.json", "")),
        ("metrics array", w("metrics.json", "[]")),
        ("metrics deep nesting", w("metrics.json", "[" * 200000 + "]" * 200000)),
        ("metrics tce NaN", edit_metrics(lambda j: j["windows"][0].__setitem__("tce", "NaN"))),
        ("metrics tce string", edit_metrics(lambda j: j["windows"][0].__setitem__("tce", "x"))),
        ("metrics no windows", edit_metrics(lambda j: j.pop("windows"))),
        ("metrics extra window", edit_metrics(lambda j: j["windows"].append(j["windows"][0]))),
        ("metrics missing", rm("metrics.json")),
        ("trajectory missing", rm("trajectory.json")),
        ("trajectory garbage", w("trajectory.json", "{")),
        ("config missing", rm("config.toml")),
        ("config garbage", w("config.toml", "name = [")),
        ("history garbage", w("history.csv", "\0\1\2not,a,csv\n1,2\n")),
        ("frame_metrics garbage", w("frame_metrics.csv", "a,b\n1\n")),
        ("report.html is a dir", lambda d: ((d / "report.html").unlink(),
                                            (d / "report.html").mkdir())),
        ("config other scene", lambda d: (d / "config.toml").write_text(
            (d / "config.toml").read_text().replace("gaussians = 5000", "gaussians = 3000"))),
    ]


# ---------------------------------------------------------------------------------------------
# Compound runners


def rerun_render_path(ctx):
    def go(c, work):
        base = ["render-path", str(ctx.fx / "demo.ply"), str(ctx.fx / "trajectory.json"),
                "--out", "rp", "--quiet", "--width", "32"]
        r1 = finish(launch(ctx.binary, base + ["--seconds", "0.4"], work, ctx.mem_gb), 60,
                    time.time())
        n1 = count_frames(work / "rp")
        r2 = finish(launch(ctx.binary, base + ["--seconds", "0.1"], work, ctx.mem_gb), 60,
                    time.time())
        n2 = count_frames(work / "rp")
        r = Result(r2.rc, r1.out + r2.out, r1.secs + r2.secs, r1.timed_out or r2.timed_out)
        if r2.rc == 0 and n2 >= n1:
            c.check = lambda w, res: ("HALF", f"second, shorter run left {n2} frames "
                                              f"(first wrote {n1}): stale frames mixed")
        return r
    return go


def count_frames(d):
    f = Path(d) / "frames"
    return len(list(f.glob("*.png"))) if f.is_dir() else 0


def concurrent(ctx, argv, outdir):
    def go(c, work):
        t0 = time.time()
        a = launch(ctx.binary, argv, work, ctx.mem_gb)
        b = launch(ctx.binary, argv, work, ctx.mem_gb)
        ra, rb = finish(a, c.timeout, t0), finish(b, c.timeout, t0)
        r = Result(ra.rc if ra.rc not in (0, 3) else rb.rc, ra.out + "\n---\n" + rb.out,
                   time.time() - t0, ra.timed_out or rb.timed_out)
        ok = [x for x in (ra, rb) if x.rc in (0, 3)]
        if not ok:
            c.check = lambda w, res: ("FAILED", f"both concurrent runs failed: rc {ra.rc}, "
                                                f"{rb.rc}")
            return r
        r.rc = 0 if len(ok) == 2 else 0
        c.check = lambda w, res: concurrent_check(w / outdir, argv, ra, rb)
        return r
    return go


def concurrent_check(out, argv, ra, rb):
    """Both succeeded: the result must be whole (frames == a video's count, no leftovers)."""
    if argv[0] == "render-path":
        n = count_frames(out)
        if n != 30:
            return ("HALF", f"two concurrent render-paths left {n} frames (30 expected)")
    if argv[0] == "run":
        dirs = [d for d in (out / "small").iterdir()] if (out / "small").is_dir() else []
        if ra.rc in (0, 3) and rb.rc in (0, 3) and len(dirs) != 2:
            return ("HALF", f"two concurrent runs, both succeeded, made {len(dirs)} run "
                            f"folder(s): they shared one")
        for d in dirs:
            if not (d / "metrics.json").exists() or not (d / "video.mp4").exists():
                return ("HALF", f"run folder {d.name} is incomplete")
    return None


def signalled(ctx, sig, delay, twice, resume):
    def go(c, work):
        t0 = time.time()
        p = launch(ctx.binary, c.argv, work, ctx.mem_gb)
        time.sleep(delay)
        sent = time.time()
        if p.poll() is None:
            os.kill(p.pid, sig)  # the process itself, as a terminal would (not its children)
            if twice:
                time.sleep(0.3)
                if p.poll() is None:
                    os.kill(p.pid, sig)
        r = finish(p, 30, t0)
        waited = time.time() - sent
        left = leftover_processes(p.pid)
        for line in left:
            try:
                os.kill(int(line.split()[0]), signal.SIGKILL)
            except (ProcessLookupError, ValueError):
                pass
        notes = []
        finished_anyway = "finished" in r.out.lower() and r.rc in (0, 3) and sig != signal.SIGKILL
        if sig != signal.SIGKILL and waited > 10 and not r.timed_out:
            notes.append(f"took {waited:.1f} s to stop after the signal")
        if left:
            notes.append(f"orphaned processes {left}")
        res_out = ""
        if resume and not r.timed_out:
            runs = sorted((work / "runs").glob("*/*")) if (work / "runs").is_dir() else []
            if runs and not (runs[-1] / "video.mp4").exists():
                rr = finish(launch(ctx.binary, ["run", "--resume", str(runs[-1]), "--quiet"],
                                   work, ctx.mem_gb), 120, time.time())
                res_out = rr.out
                if rr.rc not in (0, 3):
                    notes.append(f"--resume failed rc {rr.rc}: {rr.out.strip()[-300:]}")
                elif not (runs[-1] / "video.mp4").exists():
                    notes.append("--resume exited 0 but no video.mp4")
        r.out += "\n[resume]\n" + res_out
        if r.timed_out:
            return r
        orig = r.rc
        if sig != signal.SIGKILL and r.rc in (0, 3) and waited > 3:
            notes.append(f"the signal was not honoured: exit {r.rc} after {waited:.1f} s"
                         + (" and the run says finished" if finished_anyway else ""))
        if orig in (101, 134, -6):
            return r  # classified as PANIC/ABORT
        r.note += f" (exit {orig} after the signal, stopped {waited:.1f} s after it)"
        r.rc = 0
        if notes:
            msg = "; ".join(notes)
            c.check = lambda w, res: ("HANG" if "took" in msg or "not honoured" in msg
                                      else "HALF", msg)
        else:
            c.check = None
        return r
    return go


# ---------------------------------------------------------------------------------------------
# Main


class Ctx:
    pass


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("binary")
    ap.add_argument("--work", default="/tmp/trial/work")
    ap.add_argument("--only", default="")
    ap.add_argument("--budget-s", type=float, default=3300)
    ap.add_argument("--mem-gb", type=float, default=6)
    ap.add_argument("--json", default="")
    args = ap.parse_args()
    ctx = Ctx()
    ctx.binary = str(Path(args.binary).resolve())
    ctx.mem_gb = args.mem_gb
    work_root = Path(args.work)
    if work_root.exists():
        shutil.rmtree(work_root)
    ctx.fx = work_root / "fx"
    make_fixtures(ctx)
    define_cases(ctx)
    start = time.time()
    results = []
    selected = [c for c in CASES if args.only in c.name]
    print(f"{len(selected)} cases", flush=True)
    for i, c in enumerate(selected):
        if time.time() - start > args.budget_s:
            print(f"budget spent: stopped before case {i}", flush=True)
            break
        work = work_root / f"case-{i:04d}"
        work.mkdir()
        try:
            if c.setup:
                c.setup(work)
            guards_before = {g: identity(work / g) for g in c.guards
                             if os.path.lexists(work / g)}
            r = c.runner(c, work) if c.runner else run_plain(ctx, c, work)
            cls, note = classify(c, r, work, guards_before)
        except Exception as e:  # a fault of the trial itself, not of the binary
            cls, note, r = "TRIAL-ERROR", repr(e), Result(None, "", 0, False)
        tail = r.out.strip().splitlines()[-3:] if r.out else []
        results.append({"name": c.name, "argv": ["splatraj"] + c.argv, "class": cls,
                        "note": note + r.note, "rc": r.rc, "secs": round(r.secs, 2),
                        "expect": c.expect, "names": c.names, "tail": tail})
        print(f"[{i:4d}] {cls:9s} {r.secs:6.1f}s rc={r.rc} {c.name}"
              + (f"  -- {note}" if cls != "ok" else ""), flush=True)
        shutil.rmtree(work, ignore_errors=True)
    counts = {}
    for x in results:
        counts[x["class"]] = counts.get(x["class"], 0) + 1
    print("\nCOUNTS", json.dumps(counts, sort_keys=True))
    for x in results:
        if x["class"] != "ok":
            print(f"\n{x['class']}: {x['name']}\n  $ {' '.join(x['argv'])}\n  rc={x['rc']} "
                  f"{x['secs']}s {x['note']}\n  expected: {x['expect']} naming {x['names']}"
                  f"\n  output: {' | '.join(x['tail'])[:400]}")
    if args.json:
        Path(args.json).write_text(json.dumps({"counts": counts, "results": results}, indent=1))


if __name__ == "__main__":
    main()
