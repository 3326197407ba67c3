#!/usr/bin/env python3
"""The PyTorch peer of splatraj's mask pass, timed side by side with it on one core (issue 35).

The peer is the mask pass (render the object's mask, TCE + TRE, the gradient with respect to the
pose) written the way a researcher writes it in PyTorch, under the same rules
(docs/conventions.md, "Rendering rules" and "Optimisation problem"):

- the projection as tensor ops on every Gaussian (Rodrigues, Σ_cam, the clamped Jacobian, the
  0.3 low-pass, the conic), autograd through all of it;
- cull, radius, 16×16 tile lists and their depth order as integer data without gradient;
- each tile composited as a `[pixels, K]` tensor: α = min(0.99, o·exp(power)), α < 1/255
  skipped, T as a cumulative product, the stop before T would fall below 1e-4;
- TCE and TRE of the mask's moments, one backward.

`compare` times it two ways: over the full frame (every tile and its whole list, what the
issue's peer figure of 290 ms was), and pruned (only the tiles the object touches, each list
cut after the object's last Gaussian: the exact pruning splatraj's mask passes use).

    python3 scripts/torch_peer.py compare --binary target/release/splatraj

writes the demo scene (`splatraj scene demo`), frames its red mug at about 15 % of a 128×128
frame (60° field of view, from the demo's standing viewpoint, as `bench render` frames it),
times `splatraj render --grad` pinned to one core with one rayon thread and the peer with
one torch thread, checks that they agree (mask, loss, pose gradient) and prints one table.
Needs torch and numpy (PyPI); nothing of splatraj's build or tests needs it.
"""

import argparse
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import torch

TILE = 16
NEAR = 0.01
LOW_PASS = 0.3
FOV_CLAMP = 1.3
ALPHA_MAX = 0.99
ALPHA_MIN = 1.0 / 255.0
T_MIN = 1e-4
DET_FLOOR = 1e-12
MASS_FLOOR = 1e-3
NORM_EPSILON = 1.0 / 1_048_576.0
DEMO_VIEWPOINT = np.array([-0.3, -1.8, 1.2])
DEMO_UP = np.array([0.0, 0.0, 1.0])


# --- the scene ---------------------------------------------------------------------------------


def read_ply(path):
    """INRIA binary PLY (float and int properties) as a dict of numpy columns."""
    with open(path, "rb") as f:
        names, types, count = [], [], 0
        while True:
            line = f.readline().decode("ascii").strip()
            if line.startswith("element vertex"):
                count = int(line.split()[-1])
            elif line.startswith("property"):
                _, kind, name = line.split()
                names.append(name)
                types.append({"float": "<f4", "int": "<i4", "uchar": "u1"}[kind])
            elif line == "end_header":
                break
        data = np.frombuffer(f.read(), dtype=np.dtype(list(zip(names, types))), count=count)
    return {name: data[name] for name in names}


def label_ids(path):
    """The `comment label_name ID NAME` lines of a splatraj PLY."""
    ids = {}
    with open(path, "rb") as f:
        for raw in f:
            line = raw.decode("ascii", "replace").strip()
            if line == "end_header":
                break
            if line.startswith("comment label_name"):
                _, _, number, name = line.split(" ", 3)
                ids[name.lower()] = int(number)
    return ids


class Scene:
    """Means, world covariances, opacities and a 0/1 object mask as float32 tensors."""

    def __init__(self, path, label):
        cols = read_ply(path)
        self.means = torch.tensor(np.stack([cols["x"], cols["y"], cols["z"]], 1))
        scales = np.exp(np.stack([cols[f"scale_{i}"] for i in range(3)], 1))
        q = np.stack([cols[f"rot_{i}"] for i in range(4)], 1).astype(np.float64)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        w, x, y, z = q.T
        rot = np.stack(
            [
                1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
            ],
            1,
        ).reshape(-1, 3, 3)
        m = rot * scales[:, None, :]
        # Σ_world = R S Sᵀ Rᵀ, once per scene (rule 2).
        self.cov = torch.tensor((m @ m.transpose(0, 2, 1)).astype(np.float32))
        self.opacity = torch.tensor(1.0 / (1.0 + np.exp(-cols["opacity"].astype(np.float64)))).float()
        wanted = label_ids(path)[label.lower()]
        self.mask = torch.tensor((cols["label"] == wanted).astype(np.float32))


# --- the pass ----------------------------------------------------------------------------------


def rodrigues(omega):
    """R_wc from the rotation vector ω (θ is far from 0 for the cameras used here)."""
    theta = omega.norm()
    k = omega / theta
    zero = torch.zeros((), dtype=omega.dtype)
    kx = torch.stack(
        [
            torch.stack([zero, -k[2], k[1]]),
            torch.stack([k[2], zero, -k[0]]),
            torch.stack([-k[1], k[0], zero]),
        ]
    )
    eye = torch.eye(3, dtype=omega.dtype)
    return eye + torch.sin(theta) * kx + (1 - torch.cos(theta)) * (kx @ kx)


def project(scene, pose, camera):
    """Pixel means, conics and depths of every Gaussian, with the decisions (no gradient)."""
    fx, fy, cx, cy, width, height = camera
    r = rodrigues(pose[:3])
    p = (scene.means - pose[3:]) @ r  # [N, 3]: R_wcᵀ (p − c) per row
    x, y, z = p.unbind(1)
    z_safe = z.clamp_min(NEAR)
    xz, yz = x / z_safe, y / z_safe
    u, v = fx * xz + cx, fy * yz + cy
    lim_x, lim_y = FOV_CLAMP * 0.5 * width / fx, FOV_CLAMP * 0.5 * height / fy
    tx, ty = xz.clamp(-lim_x, lim_x), yz.clamp(-lim_y, lim_y)
    # Rows of J·W in world coordinates (rule 3): t1 = r0·fx/z − r2·fx·tx/z, and so for t2.
    t1 = (r[:, 0][None] * (fx / z_safe)[:, None]) - r[:, 2][None] * (fx * tx / z_safe)[:, None]
    t2 = (r[:, 1][None] * (fy / z_safe)[:, None]) - r[:, 2][None] * (fy * ty / z_safe)[:, None]
    s1 = torch.einsum("nij,nj->ni", scene.cov, t1)
    s2 = torch.einsum("nij,nj->ni", scene.cov, t2)
    a = (t1 * s1).sum(1) + LOW_PASS
    b = (t1 * s2).sum(1)
    c = (t2 * s2).sum(1) + LOW_PASS
    det = a * c - b * b
    with torch.no_grad():
        a64, b64, c64, z64 = a.double(), b.double(), c.double(), z.double()
        trace = a64 + c64
        det64 = a64 * c64 - b64 * b64
        kept = (z64 > NEAR) & (trace > 0) & (det64 / (trace * trace) > DET_FLOOR)
        mid = 0.5 * trace
        radius = torch.ceil(3 * torch.sqrt(mid + torch.sqrt((mid * mid - det64).clamp_min(0))))
    conic = torch.stack([c, -b, a], 1) / det[:, None]  # [N, 3]: Σ_2D⁻¹ (xx, xy, yy)
    return torch.stack([u, v], 1), conic, z, kept, radius


def tile_lists(uv, depth, kept, radius, camera, mask, pruning):
    """Per tile, its Gaussians front to back (ties by index): (tiles, starts, order)."""
    _, _, _, _, width, height = camera
    tiles_x, tiles_y = -(-width // TILE), -(-height // TILE)
    with torch.no_grad():
        ids = torch.nonzero(kept).squeeze(1)
        u, v, r = uv[ids, 0].double(), uv[ids, 1].double(), radius[ids]
        x0 = torch.floor(((u - r) / TILE).clamp(0, tiles_x)).long()
        x1 = torch.ceil(((u + r) / TILE).clamp(0, tiles_x)).long()
        y0 = torch.floor(((v - r) / TILE).clamp(0, tiles_y)).long()
        y1 = torch.ceil(((v + r) / TILE).clamp(0, tiles_y)).long()
        w, h = (x1 - x0).clamp_min(0), (y1 - y0).clamp_min(0)
        count = w * h
        owner = torch.repeat_interleave(torch.arange(len(ids)), count)
        first = torch.cumsum(count, 0) - count
        k = torch.arange(int(count.sum())) - first[owner]
        tile = (y0[owner] + k // w[owner]) * tiles_x + x0[owner] + k % w[owner]
        gaussian = ids[owner]
        # Depth first, then tile, both stable: front to back within a tile, ties by index.
        by_depth = torch.sort(depth[gaussian].detach(), stable=True).indices
        tile, gaussian = tile[by_depth], gaussian[by_depth]
        by_tile = torch.sort(tile, stable=True).indices
        tile, gaussian = tile[by_tile], gaussian[by_tile]
        counts = torch.bincount(tile, minlength=tiles_x * tiles_y)
        starts = torch.cumsum(counts, 0) - counts
        lists = []
        for t in torch.nonzero(counts).squeeze(1).tolist():
            members = gaussian[starts[t] : starts[t] + counts[t]]
            if pruning == "object":
                in_object = torch.nonzero(mask[members] > 0).squeeze(1)
                if len(in_object) == 0:
                    continue
                members = members[: int(in_object[-1]) + 1]
            lists.append((t, members))
    return tiles_x, lists


def mask_pass(scene, pose, camera, pruning, target_ratio):
    """The mask image, TCE + TRE and what backward needs."""
    fx, fy, cx, cy, width, height = camera
    uv, conic, depth, kept, radius = project(scene, pose, camera)
    tiles_x, lists = tile_lists(uv, depth, kept, radius, camera, scene.mask, pruning)
    ys, xs = torch.meshgrid(torch.arange(TILE), torch.arange(TILE), indexing="ij")
    offsets = torch.stack([xs.flatten(), ys.flatten()], 1).float()  # [256, 2]
    pieces, pixels = [], []
    for t, members in lists:
        origin = torch.tensor([(t % tiles_x) * TILE, (t // tiles_x) * TILE], dtype=torch.float32)
        pix = origin + offsets  # [256, 2]
        inside = (pix[:, 0] < width) & (pix[:, 1] < height)
        pix = pix[inside]
        d = (pix + 0.5)[:, None, :] - uv[members][None]  # [P, K, 2]
        q = conic[members]
        power = -0.5 * (q[:, 0] * d[..., 0] ** 2 + q[:, 2] * d[..., 1] ** 2) - q[:, 1] * d[..., 0] * d[..., 1]
        alpha = (scene.opacity[members] * torch.exp(power.clamp_max(0))).clamp_max(ALPHA_MAX)
        alpha = torch.where(alpha < ALPHA_MIN, torch.zeros_like(alpha), alpha)
        through = torch.cumprod(1 - alpha, 1)  # T after each Gaussian
        before = torch.cat([torch.ones_like(through[:, :1]), through[:, :-1]], 1)
        included = (through >= T_MIN).detach()
        weight = alpha * before * included
        pieces.append((weight * scene.mask[members][None]).sum(1))
        pixels.append((pix[:, 1] * width + pix[:, 0]).long())
    image = torch.zeros(width * height)
    if pieces:
        image = image.index_put((torch.cat(pixels),), torch.cat(pieces))
    image = image.reshape(height, width)
    centres = lambda n: (torch.arange(n, dtype=torch.float32) + 0.5) / n - 0.5  # noqa: E731
    mass = image.sum()
    first = torch.stack([(image.sum(0) * centres(width)).sum(), (image.sum(1) * centres(height)).sum()])
    offset = first / mass.clamp_min(MASS_FLOOR)
    tce = torch.sqrt((offset**2).sum() + NORM_EPSILON**2) - NORM_EPSILON
    tre = (mass / (width * height) - target_ratio).abs()
    return image, tce, tre


def timed_pass(scene, pose6, camera, pruning, target_ratio):
    """A forward alone (no graph, as splatraj's `forward_ms`), then a forward + backward:
    (ms forward, ms both, image, tce, tre, gradient)."""
    start = time.perf_counter()
    with torch.no_grad():
        mask_pass(scene, torch.tensor(pose6, dtype=torch.float32), camera, pruning, target_ratio)
    forward = (time.perf_counter() - start) * 1e3
    pose = torch.tensor(pose6, dtype=torch.float32, requires_grad=True)
    start = time.perf_counter()
    image, tce, tre = mask_pass(scene, pose, camera, pruning, target_ratio)
    (tce + tre).backward()
    both = (time.perf_counter() - start) * 1e3
    return forward, both, image.detach(), tce.item(), tre.item(), pose.grad.tolist()


# --- the camera and the comparison -------------------------------------------------------------


def look_at(eye, target):
    """Φ = [ω, c] of a camera at `eye` looking at `target`, its up toward the demo's up."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    down = -(DEMO_UP - DEMO_UP.dot(forward) * forward)
    down /= np.linalg.norm(down)
    right = np.cross(down, forward)
    r = np.stack([right, down, forward], 1)  # columns: camera axes in world
    angle = math.acos(max(-1.0, min(1.0, (np.trace(r) - 1) / 2)))
    if not 1e-6 < angle < math.pi - 1e-6:
        sys.exit("torch_peer: the framing camera's rotation is too near 0° or 180° for look_at")
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / (2 * math.sin(angle))
    return list(axis * angle) + list(eye)


def framing_pose(scene, camera, ratio):
    """The red mug from the demo's viewpoint at the distance where it covers `ratio`."""
    inside = scene.mask > 0
    centre = scene.means[inside].double().mean(0).numpy()
    direction = DEMO_VIEWPOINT - centre
    direction /= np.linalg.norm(direction)
    distance = 1.0
    for _ in range(4):
        pose = look_at(centre + direction * distance, centre)
        with torch.no_grad():
            image, _, _ = mask_pass(scene, torch.tensor(pose, dtype=torch.float32), camera, "object", ratio)
        coverage = image.sum().item() / (camera[4] * camera[5])
        if coverage > 0:
            distance *= math.sqrt(coverage / ratio)
    return look_at(centre + direction * distance, centre)


def ours(binary, folder, camera_file, repeats):
    """`splatraj render --grad` on one core, one rayon thread: its JSON and its mask."""
    env = dict(os.environ, RAYON_NUM_THREADS="1")
    out = os.path.join(folder, "ours")
    command = ["taskset", "-c", "0", binary, "render", "--scene", os.path.join(folder, "demo.ply"),
               "--label", "red mug", "--camera", camera_file, "--grad", "--repeats", str(repeats),
               "--out", out]
    result = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    report = json.loads(result.stdout.strip().splitlines()[-1])
    return report, np.load(os.path.join(out, "mask.npy"))


def compare(args):
    torch.set_num_threads(1)
    os.sched_setaffinity(0, {0})
    folder = args.folder or tempfile.mkdtemp(prefix="torch_peer_")
    os.makedirs(folder, exist_ok=True)
    ply = os.path.join(folder, "demo.ply")
    subprocess.run([args.binary, "scene", "demo", "--gaussians", str(args.gaussians), "--out", ply],
                   check=True, capture_output=True)
    scene = Scene(ply, "red mug")
    size = args.resolution
    f = 0.5 * size / math.tan(math.radians(args.fov) / 2)
    camera = (f, f, size / 2, size / 2, size, size)
    pose = framing_pose(scene, camera, args.target_ratio)
    camera_file = os.path.join(folder, "camera.json")
    with open(camera_file, "w") as out:
        json.dump({"fx": f, "fy": f, "cx": size / 2, "cy": size / 2, "width": size, "height": size,
                   "pose": pose}, out)
    report, our_mask = ours(args.binary, folder, camera_file, args.repeats)
    rows = []
    for pruning in ["object", "none"]:
        runs = [timed_pass(scene, pose, camera, pruning, args.target_ratio) for _ in range(args.repeats + 1)][1:]
        fwd = statistics.median(r[0] for r in runs)
        both = statistics.median(r[1] for r in runs)
        _, _, image, tce, tre, grad = runs[0]
        rows.append((pruning, fwd, both, image, tce, tre, grad))
    ours_ms = report["forward_backward_ms"]
    print(f"mask pass, demo {args.gaussians} Gaussians, {size}², red mug, coverage "
          f"{report['coverage']:.3f}; one core (taskset -c 0), splatraj with RAYON_NUM_THREADS=1, "
          f"torch {torch.__version__} with 1 thread; median of {args.repeats}")
    print(f"{'pass':<34}{'fwd ms':>9}{'fwd+bwd ms':>12}{'peer / ours':>13}")
    print(f"{'splatraj render --grad (pruned)':<34}{report['forward_ms']:>9.2f}{ours_ms:>12.2f}{'1.0':>13}")
    for pruning, fwd, both, *_ in rows:
        name = f"torch peer, pruning {pruning}"
        print(f"{name:<34}{fwd:>9.1f}{both:>12.1f}{both / ours_ms:>12.1f}×")
    print("agreement of the peer with splatraj (f32 both):")
    ours_grad = np.array(report["grad_pose"])
    for pruning, _, _, image, tce, tre, grad in rows:
        grad = np.array(grad)
        mask_diff = np.abs(image.numpy() - our_mask.reshape(image.shape)).max()
        grad_diff = np.abs(grad - ours_grad).max() / max(np.abs(ours_grad).max(), 1e-12)
        print(f"  pruning {pruning}: mask max |Δ| {mask_diff:.2e}, loss {tce + tre:.6f} vs "
              f"{report['loss']:.6f}, pose gradient max |Δ| {grad_diff:.2e} of its largest component")
        # f32 on both sides, summed in other orders: measured 4.6e-6, 0 and 3.0e-6.
        if mask_diff > 1e-4 or abs(tce + tre - report["loss"]) > 1e-5 or grad_diff > 1e-4:
            sys.exit(f"the peer and splatraj disagree (pruning {pruning}): not the same pass")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("compare", help="time the peer and splatraj side by side on one core")
    run.add_argument("--binary", required=True, help="a release build of splatraj")
    run.add_argument("--gaussians", type=int, default=100_000)
    run.add_argument("--resolution", type=int, default=128)
    run.add_argument("--fov", type=float, default=60.0, help="horizontal field of view, degrees")
    run.add_argument("--target-ratio", type=float, default=0.15)
    run.add_argument("--repeats", type=int, default=9)
    run.add_argument("--folder", help="where the scene, camera and renders go (default: a new temporary folder)")
    args = parser.parse_args()
    compare(args)


if __name__ == "__main__":
    main()
