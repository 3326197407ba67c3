#!/usr/bin/env python3
"""Writes the fixtures of splatraj-camera-paths' tests/tools.rs (crates/splatraj-camera-paths/tests/data/tools/):
our camera exports as the real tools load them, and camera paths made by those tools.

The references:
- nerfstudio's own loader, `nerfstudio.cameras.camera_paths.get_path_from_json` (nerfstudio
  1.1.5 from PyPI), applied to our `camera_path.json` exports; and its `get_spiral_path`, whose
  Cameras are written as a camera_path.json in the schema of nerfstudio's viewer render panel
  (`nerfstudio/viewer/render_panel.py`, the `json_data` it saves: keyframes, render size, fps,
  seconds, `camera_path` entries of flattened 4x4 `camera_to_world`, `fov` in degrees,
  `aspect`). Torch's default dtype is set to float64 first: the loader's maths is unchanged,
  but `torch.tensor(list)` would otherwise round every matrix and focal length to float32.
- pycolmap (PyPI `pycolmap`, COLMAP's own bindings): `pycolmap.Reconstruction(dir)` of our
  COLMAP text model exports; and a model built in pycolmap (PINHOLE camera, images with
  `cam_from_world`) and written by `Reconstruction.write_text` (`write` picks binary, which our
  reader does not read) to `pycolmap_model/`.
- The graphdeco-inria/gaussian-splatting code's meaning of a `cameras.json` entry, its maths
  re-done here in numpy (the repository is not a package): `utils/camera_utils.py`
  `camera_to_JSON` writes `position` = C2W[:3, 3] and `rotation` = C2W[:3, :3] with
  C2W = inv(W2C), W2C = [R^T | T] (the rotation R their Camera holds is camera-to-world, T the
  world-to-camera translation: `scene/dataset_readers.py` `readColmapCameras`,
  R = qvec2rotmat(qvec)^T, T = tvec), `fx` = fov2focal(FovX, width), `fy` = fov2focal(FovY,
  height) (`utils/graphics_utils.py`: fov2focal(f, p) = p / (2 tan(f/2)), focal2fov its
  inverse); so an entry gives R = rotation, T = -R^T position, FoVx = focal2fov(fx, width),
  FoVy = focal2fov(fy, height), and their world-to-view matrix getWorld2View2(R, T) (identity
  translate, scale 1) = [R^T | T].

Run (after `SPLATRAJ_WRITE_TOOL_INPUTS=1 cargo test -p splatraj-camera-paths --test tools`
has written `ours/` and `ours_cut_zoom/`, if our exports changed):
    python3 -m venv --system-site-packages /tmp/nsenv     # torch from the system, if it has one
    /tmp/nsenv/bin/pip install --no-deps nerfstudio==1.1.5
    /tmp/nsenv/bin/pip install jaxtyping opencv-python-headless viser pycolmap numpy
    /tmp/nsenv/bin/python scripts/make_tool_fixtures.py [DATA_DIR]
(nerfstudio's full dependency set, with tinycudann, gsplat, etc., is not needed to import
`nerfstudio.cameras.camera_paths`.) Without a system torch: PyPI's Linux x86-64 torch wheel is
a CUDA build that does not import without its nvidia-* libraries, even on CPU; `pip install
torch` brings them all (with triton and the CUDA toolkit, several GB), while `pip install
--no-deps torch` plus the nvidia-* wheels its metadata names (cuBLAS, cuDNN, cuFFT, cuSPARSE,
cuSPARSELt, cuSOLVER, NCCL, NVSHMEM, cuFile, CUPTI, NVRTC, CUDA runtime, nvJitLink) and
filelock, fsspec is about 4 GB and enough (torch 2.15.0 wrote the current fixtures).

Two of our exports are loaded, each written by tools.rs with SPLATRAJ_WRITE_TOOL_INPUTS=1:
`ours/` (one shot, one fixed camera) and `ours_cut_zoom/` (three shots, two cuts, a focal length
that changes frame by frame, fy 420 to 1100). What the tools do NOT carry, shown here by loading
each file again without it and getting the same cameras (`same_without` in each *_loaded file):
- nerfstudio's get_path_from_json ignores `cuts` and `keyframes` (the viewer's; its "Load Path"
  runs inside the viewer's GUI, not started here, so tools.rs checks the keyframes in the file);
  it takes each frame's fov from its own entry, so the zoom comes through, and a cut is two
  consecutive `camera_path` entries;
- COLMAP skips the `# splatraj cuts:` comment of images.txt, and pycolmap's write_text drops it
  (`cuts_comment_kept_by_write_text`: false): a model resaved by COLMAP loses the cuts; the zoom
  is one camera per focal length, each image naming its own;
- the graphdeco code reads no `shot`; FoVx, FoVy come from each entry's own fx, fy.
The SuperSplat settings.json in ours_cut_zoom/ is read back by our reader only (tools.rs): the
viewer is TypeScript; tests/supersplat_keys.rs transcribes its playback.

Writes, under DATA_DIR (default crates/splatraj-camera-paths/tests/data/tools), for each export
folder (SUFFIX "" for ours/, "_cut_zoom" for ours_cut_zoom/):
- nerfstudio_loadedSUFFIX.json  per frame of camera_path.json: camera_to_world (3x4), fx,
                              fy, cx, cy, width, height as get_path_from_json's Cameras hold them;
                              same_without
- pycolmap_loadedSUFFIX.json    per image (by id): id, name, camera_id, cam_from_world (3x4);
                              per camera: model, width, height, params; same_without and, where
                              images.txt has the cuts comment, cuts_comment_kept_by_write_text
- inria_loadedSUFFIX.json       per entry of cameras.json: R, T, world_view (4x4), FoVx, FoVy;
                              same_without
and once:
- nerfstudio_spiral/camera_path.json, truth.json   the spiral path and its Cameras (checked
                              here to read back through get_path_from_json unchanged)
- pycolmap_model/{cameras,images,points3D,rigs,frames}.txt, truth.json   the model and its
                              images' cam_from_world and camera params
"""

import json
import math
import os
import sys
import tempfile

import numpy as np
import pycolmap
import torch

torch.set_default_dtype(torch.float64)

from nerfstudio.cameras.camera_paths import get_path_from_json, get_spiral_path  # noqa: E402
from nerfstudio.cameras.cameras import Cameras  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
    HERE, "..", "crates", "splatraj-camera-paths", "tests", "data", "tools")
# Our export folders and the suffix of what the tools loaded of each (tools.rs FIXTURES).
EXPORTS = [("ours", ""), ("ours_cut_zoom", "_cut_zoom")]
CUTS_COMMENT = "# splatraj cuts:"


def write_json(rel, value):
    path = os.path.join(DATA, rel)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as f:
        json.dump(value, f, indent=1)
        f.write("\n")
    print("wrote", path)


def cameras_dict(cams: Cameras):
    """Per camera of a nerfstudio Cameras: what tools.rs compares."""
    out = []
    for i in range(cams.camera_to_worlds.shape[0]):
        out.append({
            "camera_to_world": cams.camera_to_worlds[i].tolist(),
            "fx": float(cams.fx[i]), "fy": float(cams.fy[i]),
            "cx": float(cams.cx[i]), "cy": float(cams.cy[i]),
            "width": int(cams.width[i]), "height": int(cams.height[i]),
        })
    return out


def same_without(load, value, keys, drop):
    """The keys of `keys` that `value` holds and `load` does not depend on: drop(value, key)
    differs from `value` and loads to what `value` loads to."""
    full = load(value)
    return [k for k in keys if drop(value, k) != value and load(drop(value, k)) == full]


def drop_key(value, key):
    """A JSON object without `key`, or a JSON array of objects each without it."""
    if isinstance(value, list):
        return [drop_key(v, key) for v in value]
    return {k: v for k, v in value.items() if k != key}


def nerfstudio_load(camera_path):
    cams = get_path_from_json(camera_path)
    assert cams.camera_to_worlds.dtype == torch.float64
    return cameras_dict(cams)


def nerfstudio_loads_ours(folder, suffix):
    with open(os.path.join(DATA, folder, "camera_path.json")) as f:
        path = json.load(f)
    write_json(f"nerfstudio_loaded{suffix}.json", {
        "tool": "nerfstudio 1.1.5 nerfstudio.cameras.camera_paths.get_path_from_json",
        "same_without": same_without(nerfstudio_load, path, ["cuts", "keyframes"], drop_key),
        "cameras": nerfstudio_load(path)})


def pycolmap_load(text_folder):
    """Images (by id) and cameras of pycolmap.Reconstruction(dir)."""
    rec = pycolmap.Reconstruction(text_folder)
    images = []
    for image_id in sorted(rec.images):
        im = rec.images[image_id]
        images.append({"id": image_id, "name": im.name, "camera_id": im.camera_id,
                       "cam_from_world": im.cam_from_world().matrix().tolist()})
    cameras = {str(cid): {"model": cam.model.name, "width": cam.width, "height": cam.height,
                          "params": list(cam.params)}
               for cid, cam in rec.cameras.items()}
    return {"images": images, "cameras": cameras}


def pycolmap_load_images_txt(model, images_txt):
    """pycolmap_load of the model folder `model` with `images_txt` as its images.txt (its
    cameras.txt and points3D.txt linked into a temporary folder)."""
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("cameras.txt", "points3D.txt"):
            os.symlink(os.path.abspath(os.path.join(model, name)), os.path.join(tmp, name))
        with open(os.path.join(tmp, "images.txt"), "w") as f:
            f.write(images_txt)
        return pycolmap_load(tmp)


def drop_comment(text, prefix):
    """`text` without its lines that start with `prefix`."""
    return "".join(line for line in text.splitlines(True) if not line.startswith(prefix))


def pycolmap_loads_ours(folder, suffix):
    model = os.path.join(DATA, folder)
    with open(os.path.join(model, "images.txt")) as f:
        images_txt = f.read()
    loaded = pycolmap_load(model)

    def load(text):
        return pycolmap_load_images_txt(model, text)

    # The copy in a temporary folder loads as the model itself.
    assert load(images_txt) == loaded
    out = {"tool": f"pycolmap {pycolmap.__version__} Reconstruction(dir)",
           "same_without": same_without(load, images_txt, [CUTS_COMMENT], drop_comment)}
    if CUTS_COMMENT in images_txt:
        with tempfile.TemporaryDirectory() as tmp:
            pycolmap.Reconstruction(model).write_text(tmp)
            with open(os.path.join(tmp, "images.txt")) as f:
                out["cuts_comment_kept_by_write_text"] = CUTS_COMMENT in f.read()
    out.update(loaded)
    write_json(f"pycolmap_loaded{suffix}.json", out)


def focal2fov(focal, pixels):
    """graphdeco utils/graphics_utils.py focal2fov."""
    return 2 * math.atan(pixels / (2 * focal))


def get_world2view2(R, t):
    """graphdeco utils/graphics_utils.py getWorld2View2 with translate 0, scale 1."""
    Rt = np.zeros((4, 4))
    Rt[:3, :3] = R.transpose()
    Rt[:3, 3] = t
    Rt[3, 3] = 1.0
    C2W = np.linalg.inv(Rt)
    W2C = np.linalg.inv(C2W)
    return W2C


def graphdeco_load(entries):
    """Per entry of a cameras.json, what the graphdeco code makes of it."""
    out = []
    for e in entries:
        # camera_to_JSON: rotation = C2W[:3, :3], position = C2W[:3, 3]; W2C = inv(C2W) holds
        # [R^T | T], so R = rotation and T = W2C[:3, 3].
        C2W = np.eye(4)
        C2W[:3, :3] = np.array(e["rotation"])
        C2W[:3, 3] = np.array(e["position"])
        W2C = np.linalg.inv(C2W)
        R = W2C[:3, :3].transpose()
        T = W2C[:3, 3]
        out.append({"id": e["id"], "R": R.tolist(), "T": T.tolist(),
                    "world_view": get_world2view2(R, T).tolist(),
                    "FoVx": focal2fov(e["fx"], e["width"]), "FoVy": focal2fov(e["fy"], e["height"])})
    return out


def graphdeco_reads_ours(folder, suffix):
    with open(os.path.join(DATA, folder, "cameras.json")) as f:
        entries = json.load(f)
    write_json(f"inria_loaded{suffix}.json", {
        "tool": "graphdeco-inria/gaussian-splatting maths: utils/camera_utils.py camera_to_JSON, "
                "scene/dataset_readers.py readColmapCameras, utils/graphics_utils.py",
        # Each entry's `shot`: dropped from every entry at once.
        "same_without": same_without(graphdeco_load, entries, ["shot"], drop_key),
        "cameras": graphdeco_load(entries)})


def nerfstudio_spiral():
    # A start camera 3 units back, looking down −z in nerfstudio's OpenGL axes, tilted a little.
    a = 0.2
    c2w = torch.tensor([[1.0, 0.0, 0.0, 0.5],
                        [0.0, math.cos(a), -math.sin(a), 0.2],
                        [0.0, math.sin(a), math.cos(a), 3.0]])
    start = Cameras(camera_to_worlds=c2w[None], fx=500.0, fy=500.0, cx=320.0, cy=240.0,
                    width=640, height=480)
    spiral = get_spiral_path(start, steps=24, radius=0.5, rots=1, zrate=0.5)
    width, height, fps = 640, 480, 24.0
    fov = math.degrees(2 * math.atan(height / (2 * float(spiral.fy[0]))))

    def matrix(i):
        m = torch.eye(4)
        m[:3] = spiral.camera_to_worlds[i]
        return m.flatten().tolist()

    n = spiral.camera_to_worlds.shape[0]
    path = {
        # render_panel.py's json_data keys, in its order.
        "default_fov": fov,
        "default_transition_sec": 0.25,
        "keyframes": [{"matrix": matrix(i), "fov": fov, "aspect": width / height,
                       "override_transition_enabled": False, "override_transition_sec": None}
                      for i in range(0, n, 6)],
        "camera_type": "perspective",
        "render_height": height,
        "render_width": width,
        "fps": fps,
        "seconds": n / fps,
        "is_cycle": True,
        "smoothness_value": 0.5,
        "camera_path": [{"camera_to_world": matrix(i), "fov": fov, "aspect": width / height}
                        for i in range(n)],
    }
    write_json("nerfstudio_spiral/camera_path.json", path)
    back = get_path_from_json(path)
    assert torch.allclose(back.camera_to_worlds, spiral.camera_to_worlds, atol=1e-12)
    assert torch.allclose(back.fy, spiral.fy.expand(n, 1), atol=1e-9)
    truth = cameras_dict(back)
    write_json("nerfstudio_spiral/truth.json", {
        "tool": "nerfstudio 1.1.5 get_spiral_path(steps=24, radius=0.5, rots=1, zrate=0.5), "
                "read back by get_path_from_json", "cameras": truth})


def pycolmap_model():
    rec = pycolmap.Reconstruction()
    cams = [pycolmap.Camera(model="PINHOLE", width=800, height=600,
                            params=[700.5, 690.25, 401.0, 298.5], camera_id=1),
            pycolmap.Camera(model="PINHOLE", width=800, height=600,
                            params=[650.0, 655.0, 399.0, 301.0], camera_id=2)]
    for cam in cams:
        rec.add_camera_with_trivial_rig(cam)
    rng = np.random.default_rng(26)
    for i in range(6):
        q = rng.normal(size=4)  # x, y, z, w
        q /= np.linalg.norm(q)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(q), rng.normal(size=3) * 2.0)
        image = pycolmap.Image(name=f"view_{i:02}.jpg", camera_id=1 + i % 2, image_id=i + 1)
        rec.add_image_with_trivial_frame(image, pose)
    folder = os.path.join(DATA, "pycolmap_model")
    os.makedirs(folder, exist_ok=True)
    rec.write_text(folder)
    back = pycolmap.Reconstruction(folder)
    images = [{"id": i, "name": back.images[i].name,
               "cam_from_world": back.images[i].cam_from_world().matrix().tolist(),
               "params": list(back.cameras[back.images[i].camera_id].params)}
              for i in sorted(back.images)]
    write_json("pycolmap_model/truth.json", {
        "tool": f"pycolmap {pycolmap.__version__} Reconstruction.write_text", "images": images})


if __name__ == "__main__":
    for export_folder, export_suffix in EXPORTS:
        nerfstudio_loads_ours(export_folder, export_suffix)
        pycolmap_loads_ours(export_folder, export_suffix)
        graphdeco_reads_ours(export_folder, export_suffix)
    nerfstudio_spiral()
    pycolmap_model()
