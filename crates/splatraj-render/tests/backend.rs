//! Every compiled backend (flex by default; ndarray and wgpu with their features) renders the
//! same image as the independent f64 reference renderer, and the same pose gradient as flex in
//! f64 (itself checked against finite differences in tests/rasterizer.rs).

mod common;

use burn::tensor::{DType, Tensor, TensorData};
use common::{host, ref_camera};
use glam::DVec3;
use splatraj_render::backend::{BackendKind, Hardware, Precision};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::reference::{RefChannels, render_reference};
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, Pruning, Rasterizer, RenderRequest, render,
};
use splatraj_scene::Scene;

/// A 5×4 grid of overlapping Gaussians at depth ~3 in front of a camera looking along +z;
/// every third belongs to the object mask.
fn scene() -> (Scene, Vec<f32>) {
    let mut scene = Scene::default();
    let mut mask = Vec::new();
    for i in 0..20 {
        let (gx, gy) = ((i % 5) as f32, (i / 5) as f32);
        scene
            .means
            .push([0.35 * (gx - 2.0), 0.3 * (gy - 1.5), 3.0 + 0.1 * gx]);
        scene.scales.push([0.12 + 0.02 * gy, 0.08, 0.05]);
        let angle = 0.3 * i as f32;
        scene
            .rotations
            .push([(angle / 2.0).cos(), 0.0, 0.0, (angle / 2.0).sin()]);
        scene.opacities.push(0.5 + 0.025 * i as f32);
        scene.sh.extend([0.2 * gx - 0.4, 0.1 * gy, -0.3]);
        mask.push(if i % 3 == 0 { 1.0 } else { 0.0 });
    }
    (scene, mask)
}

fn setup() -> (Scene, Vec<f32>, Intrinsics, Pose) {
    let (scene, mask) = scene();
    let intrinsics = Intrinsics::new(40.0, 40.0, 24.0, 17.0, 48, 34).unwrap();
    let pose = Pose::look_at(
        DVec3::new(0.1, -0.05, 0.0),
        DVec3::new(0.0, 0.0, 3.0),
        DVec3::new(0.0, -1.0, 0.0),
    )
    .unwrap();
    (scene, mask, intrinsics, pose)
}

/// Mask image and d(Σ mask)/dΦ on a backend with a rasterizer, alpha returned or dropped.
fn mask_and_gradient(
    backend: BackendKind,
    precision: Precision,
    rasterizer: Rasterizer,
    alpha: AlphaChannel,
) -> (Vec<f64>, Vec<f64>) {
    let (scene, mask, intrinsics, pose) = setup();
    let device = backend.device().expect("compiled backend").autodiff();
    let dtype = precision.dtype();
    let uploaded = DeviceScene::new(&scene, &device, dtype);
    let poses = Tensor::<2>::from_data(TensorData::new(pose.0.to_vec(), [1, 6]), (&device, dtype))
        .require_grad();
    let mut request = RenderRequest::new(intrinsics, vec![Channel::Mask(mask)]);
    request.pruning = Pruning::ObjectOnly;
    request.rasterizer = rasterizer;
    request.alpha = alpha;
    let out = render(&uploaded, poses.clone(), &request).unwrap();
    assert_eq!(out.images.dims()[3], 1, "one mask channel");
    assert_eq!(out.alpha().is_some(), alpha == AlphaChannel::Returned);
    let grads = out.images.clone().sum().backward();
    let image = host(out.images);
    let grad = host(poses.grad(&grads).unwrap());
    (image, grad)
}

fn reference_mask() -> Vec<f64> {
    let (scene, mask, k, pose) = setup();
    let camera = ref_camera(&pose, &k);
    render_reference(
        &scene,
        &camera,
        &RefChannels {
            rgb: false,
            depth: false,
            masks: vec![&mask],
        },
    )
    .masks
    .remove(0)
}

#[test]
fn compiled_backends_agree_on_image_and_gradient() {
    let compiled = BackendKind::compiled();
    assert!(
        !compiled.is_empty(),
        "a build without any backend cannot render"
    );
    let reference = reference_mask();
    assert!(reference.iter().any(|&v| v > 0.2), "the object is in view");
    let (_, flex_grad) = mask_and_gradient(
        BackendKind::Flex,
        Precision::F64,
        Rasterizer::Tensor,
        AlphaChannel::Returned,
    );
    assert!(
        flex_grad.iter().any(|g| g.abs() > 1e-3),
        "a gradient to compare"
    );
    for backend in compiled {
        let precisions: &[Precision] = if backend == BackendKind::Wgpu {
            &[Precision::F32]
        } else {
            &[Precision::F32, Precision::F64]
        };
        // Dropping alpha changes the fused op's output and its backward's input (no alpha
        // column): the same mask and gradient either way.
        for (&precision, rasterizer, alpha) in precisions.iter().flat_map(|p| {
            [Rasterizer::Fused, Rasterizer::Tensor]
                .into_iter()
                .flat_map(move |r| {
                    [AlphaChannel::Returned, AlphaChannel::Dropped].map(|a| (p, r, a))
                })
        }) {
            let (image, grad) = mask_and_gradient(backend, precision, rasterizer, alpha);
            let tolerance = if precision == Precision::F64 {
                1e-9
            } else {
                1e-4
            };
            let image_error = image
                .iter()
                .zip(&reference)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(
                image_error <= tolerance,
                "{backend} {precision:?} {rasterizer:?} {alpha:?}: image differs by {image_error}"
            );
            for (k, (got, want)) in grad.iter().zip(&flex_grad).enumerate() {
                let relative = (got - want).abs() / want.abs().max(1.0);
                assert!(
                    relative <= 1e-3,
                    "{backend} {precision:?} {rasterizer:?} {alpha:?}: dΦ[{k}] = {got}, flex f64 tensor says {want}"
                );
            }
        }
    }
}

/// The 8-bit levels packed where the images are (`images::packed_rgb8`, what a GPU's frames
/// read back) are `rgb8`'s on the host, but for values within 1e-5 of half a level, which f32
/// may round to the level above: one level apart, and few of them.
#[test]
fn packed_levels_are_rgb8_s_on_every_backend() {
    use splatraj_render::images::{packed_rgb8, rgb8, unpack_rgb8};

    let (batch, height, width, channels) = (2, 30, 41, 4);
    let count = batch * height * width * channels;
    let mut rng = common::Rng(0x51f1_5eed);
    let mut pixels: Vec<f32> = (0..count).map(|_| rng.range(-0.2, 1.2) as f32).collect();
    // Each level's half and its f32 neighbours, the levels themselves, and the edges.
    let mut special = vec![0.0f32, -0.0, 1.0, -1.0, 2.0, f32::INFINITY, -f32::INFINITY];
    for k in 0..=255u8 {
        let half = ((f64::from(k) + 0.5) / 255.0) as f32;
        special.extend([half, half.next_up(), half.next_down(), f32::from(k) / 255.0]);
    }
    pixels[..special.len()].copy_from_slice(&special);
    let want = rgb8(&pixels, channels, None);
    let values: Vec<f32> = pixels
        .chunks_exact(channels)
        .flat_map(|px| px[..3].to_vec())
        .collect();
    for backend in BackendKind::compiled() {
        let images = Tensor::<4>::from_data(
            TensorData::new(pixels.clone(), [batch, height, width, channels]),
            (&backend.device().unwrap(), DType::F32),
        );
        let pack = |images: Tensor<4>| -> Vec<i32> {
            packed_rgb8(images)
                .into_data()
                .convert::<i32>()
                .try_into_vec::<i32>()
                .unwrap()
        };
        // The colour channels as a strided view (the mask cut away): the same levels.
        let view = pack(images.clone().narrow(3, 0, 3));
        let packed = pack(images);
        assert_eq!(view, packed, "{backend}: a strided view packs as the whole");
        assert_eq!(packed.len(), batch * height * width, "{backend}");
        let got = unpack_rgb8(&packed);
        let mut apart = 0;
        for ((&got, &want), &v) in got.iter().zip(&want).zip(&values) {
            if got != want {
                let level = f64::from(v).clamp(0.0, 1.0) * 255.0;
                let from_half = (level - level.floor() - 0.5).abs();
                assert!(
                    from_half < 1e-5 && got.abs_diff(want) == 1,
                    "{backend}: {v:e} packs to level {got}, rgb8 gives {want}"
                );
                apart += 1;
            }
        }
        // A handful at most (1 on flex with this seed), though 768 values lie a rounding from
        // a half.
        assert!(
            apart <= 16,
            "{backend}: {apart} of {} levels apart",
            values.len()
        );
    }
}

#[test]
fn missing_backend_names_its_feature() {
    for backend in BackendKind::ALL.into_iter().filter(|b| !b.is_compiled()) {
        let message = backend.device().unwrap_err().to_string();
        assert!(
            message.contains(&format!("--features {}", backend.feature())),
            "{message}"
        );
    }
    assert_eq!("cpu".parse::<BackendKind>(), Ok(BackendKind::Flex));
    assert!(
        "cuda"
            .parse::<BackendKind>()
            .unwrap_err()
            .contains("unknown backend 'cuda'")
    );
}

/// What each compiled backend runs on, as runs report it: the CPU with rayon's threads, and on
/// wgpu the adapter by name, Mesa's software one (lavapipe, named "llvmpipe") as an emulated
/// GPU with a warning that names it and says what to install.
#[test]
fn each_backend_says_what_it_runs_on() {
    for backend in BackendKind::compiled() {
        let hardware = Hardware::of(&backend.device().unwrap());
        match backend {
            BackendKind::Flex | BackendKind::Ndarray => {
                assert_eq!(
                    hardware,
                    Hardware::Cpu {
                        threads: rayon::current_num_threads()
                    }
                );
                assert_eq!(hardware.warning(), None);
            }
            BackendKind::Wgpu => match &hardware {
                Hardware::EmulatedGpu { name } => {
                    assert!(
                        name.contains("llvmpipe"),
                        "{name}: only lavapipe is known here"
                    );
                    let warning = hardware.warning().expect("a warning");
                    assert!(
                        warning.contains(name.as_str()) && warning.contains("Vulkan driver"),
                        "{warning}"
                    );
                }
                Hardware::Gpu { name } => {
                    assert!(!name.contains("llvmpipe"), "{name} is software");
                    assert_eq!(hardware.warning(), None);
                }
                Hardware::Cpu { .. } => panic!("wgpu reported as the host's cores"),
            },
        }
    }
}

/// `splatraj devices` marks the adapter a run takes and gives each the
/// `CUBECL_WGPU_DEFAULT_DEVICE` value that picks it. CubeCL's own device start is the yardstick:
/// the adapter marked is the one whose name the started device reports, and each listed value,
/// set in a process of its own (the adapter is chosen once a process), starts a device of the
/// listed name.
#[cfg(feature = "wgpu")]
#[test]
fn the_listed_adapters_are_the_ones_a_run_starts() {
    use splatraj_render::adapters::{SELECTOR_VARIABLE, wgpu_adapters};
    const CHILD: &str = "SPLATRAJ_TEST_LISTED_ADAPTER_NAME";
    let started = |expected: &str| match Hardware::of(&BackendKind::Wgpu.device().unwrap()) {
        Hardware::Gpu { name } | Hardware::EmulatedGpu { name } => {
            assert_eq!(name, expected, "the device started is not the one listed")
        }
        Hardware::Cpu { .. } => panic!("wgpu reported as the host's cores"),
    };
    if let Ok(expected) = std::env::var(CHILD) {
        started(&expected);
        return;
    }
    // The device first: CubeCL and the listing each make a Vulkan instance, and the loader
    // does not like two made at once.
    let variable = std::env::var(SELECTOR_VARIABLE).ok();
    BackendKind::Wgpu.device().unwrap();
    let listing = wgpu_adapters(variable.as_deref()).unwrap();
    assert!(
        !listing.adapters.is_empty(),
        "a device started, so wgpu has an adapter"
    );
    started(&listing.taken().expect("the adapter a run takes").name);
    for adapter in &listing.adapters {
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "the_listed_adapters_are_the_ones_a_run_starts",
                "--nocapture",
            ])
            .env(CHILD, &adapter.name)
            .env(SELECTOR_VARIABLE, adapter.selector.to_string())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}={}: {:?}: {}",
            SELECTOR_VARIABLE,
            adapter.selector,
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

/// f64 asked of a device without 64-bit floats is an error before any work, naming the device
/// and the way out: wgpu on OpenGL (Metal, some GPUs) has none, and a pass then failed to compile
/// a kernel and ended in a panic (found running the lavapipe tests with wgpu on Mesa's OpenGL).
/// Lavapipe's Vulkan has them. The OpenGL case runs in a child process whose Vulkan loader finds
/// no driver (`VK_DRIVER_FILES` naming none), so wgpu settles on OpenGL where the machine has it.
#[cfg(feature = "wgpu")]
#[test]
fn f64_is_refused_where_the_device_has_none() {
    use splatraj_render::backend::{BackendUnavailable, has_f64};
    const CHILD: &str = "SPLATRAJ_TEST_NO_F64_CHILD";
    if std::env::var_os(CHILD).is_some() {
        let Ok(device) = BackendKind::Wgpu.device() else {
            println!("no OpenGL adapter either: nothing to check");
            return;
        };
        assert!(!has_f64(&device), "wgpu on OpenGL offers no f64");
        assert!(BackendKind::Wgpu.device_for(DType::F32).is_ok());
        let refused = BackendKind::Wgpu.device_for(DType::F64).unwrap_err();
        assert!(matches!(refused, BackendUnavailable::NoFloat64 { .. }));
        let message = refused.to_string();
        assert!(
            message.contains("no 64-bit floats") && message.contains("precision = \"f32\""),
            "{message}"
        );
        println!("refused: {message}");
        return;
    }
    // The host backends and lavapipe's Vulkan have f64 (this test run on OpenGL has not).
    for backend in BackendKind::compiled() {
        let device = backend.device().unwrap();
        let host = matches!(backend, BackendKind::Flex | BackendKind::Ndarray);
        assert!(!host || has_f64(&device), "{backend}: a CPU has f64");
        assert_eq!(
            backend.device_for(DType::F64).is_ok(),
            has_f64(&device),
            "{backend}"
        );
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "f64_is_refused_where_the_device_has_none",
            "--nocapture",
        ])
        .env(CHILD, "1")
        .env("VK_DRIVER_FILES", "/nonexistent/no_icd.json")
        .env_remove("CUBECL_WGPU_DEFAULT_DEVICE")
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{:?}: {said}{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    eprintln!(
        "{}",
        said.lines()
            .find(|l| l.starts_with("refused") || l.starts_with("no OpenGL"))
            .unwrap_or("")
    );
}

/// A wgpu that cannot start a device is an error that says what wgpu said and what to do, the
/// second time too, not a panic on burn's device thread (an "internal error", exit 101, until
/// 30 November). Its own process: the adapter is chosen once per process, here one that no
/// machine has (`CUBECL_WGPU_DEFAULT_DEVICE`, read when the device starts).
#[cfg(feature = "wgpu")]
#[test]
fn a_gpu_that_cannot_start_is_an_error() {
    const CHILD: &str = "SPLATRAJ_TEST_NO_DEVICE_CHILD";
    const NO_SUCH_GPU: &str = "DiscreteGpu(200)";
    if std::env::var_os(CHILD).is_some() {
        for _ in 0..2 {
            let message = BackendKind::Wgpu.device().unwrap_err().to_string();
            assert!(
                message.contains("could not start a device")
                    && message.contains(NO_SUCH_GPU)
                    && message.contains("backend = \"flex\""),
                "{message}"
            );
        }
        return;
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args([
            "--exact",
            "a_gpu_that_cannot_start_is_an_error",
            "--nocapture",
        ])
        .env(CHILD, "1")
        .env("CUBECL_WGPU_DEFAULT_DEVICE", NO_SUCH_GPU)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn f64_is_really_f64() {
    let device = BackendKind::Flex.device().unwrap();
    let x = Tensor::<1>::from_data(
        TensorData::new(vec![1.0f64 + 1e-12], [1]),
        (&device, DType::F64),
    );
    assert_eq!(host(x)[0], 1.0 + 1e-12);
}

/// The GPU kernels against the host kernels, both f32, on a batch that stresses the kernels'
/// own structure: lists longer than one shared-memory stage (256), opaque stacks that stop
/// pixels and whole tiles early, partial tiles, an empty tile, two channels, two poses; each
/// list composited whole by one workgroup. The host kernels are themselves checked against the
/// tensor path in f64 (`tests/fused.rs`).
#[cfg(feature = "wgpu")]
#[test]
fn gpu_kernels_match_host_kernels() {
    let device = BackendKind::Wgpu.device().unwrap();
    assert_eq!(
        splatraj_render::fused::cube::entry_sums_on(&device, 2),
        Some(splatraj_render::fused::cube::EntrySums::Pipelined),
        "lavapipe's workgroup memory holds the pipelined backward of two channels"
    );
    gpu_kernels_match_host_kernels_with(600, 2, WHOLE_LISTS);
}

/// The same with the lists cut into the shortest segments, one forward stage (256 entries):
/// lists of up to ~600 entries in two or three segments, pixels that stop inside a segment
/// (the later segments of their tile composite nothing), whole tiles that stop early, each
/// segment replaying alone with the colour the later ones put behind it.
#[cfg(feature = "wgpu")]
#[test]
fn gpu_kernels_match_host_kernels_on_lists_cut_into_segments() {
    gpu_kernels_match_host_kernels_with(600, 2, STAGE_ENTRIES);
}

/// Segments at their edges, one pose of five tiles cut into two-stage segments: a list of
/// exactly one segment, of exactly two (the boundary at its end saves nothing), of one segment
/// and one entry (a one-entry last segment), an empty list, and a list of four segments whose
/// first entries are opaque so that every pixel stops in the first stage: the tile ends early
/// inside its first segment, which is written with its contributors, and its three later
/// segments as it stopped, with none. The other lists are faint enough that T stays above the
/// stop across segments.
#[cfg(feature = "wgpu")]
#[test]
fn gpu_kernels_match_host_kernels_at_segment_edges() {
    use splatraj_render::tiles::{TILE_SIZE, TileGrid, TileWork};

    let segment = 2 * STAGE_ENTRIES;
    let lengths = [segment, 2 * segment, segment + 1, 0, 4 * segment];
    let opaque_front = 40;
    let channels = 2;
    let grid = TileGrid::new(lengths.len() * TILE_SIZE, TILE_SIZE);
    let mut rng = common::Rng(0x51ab);
    let (mut means, mut conics, mut opacities, mut values) = (vec![], vec![], vec![], vec![]);
    let mut work = Vec::new();
    let mut next = 0u32;
    for (tile, &length) in lengths.iter().enumerate() {
        let centre = (tile * TILE_SIZE) as f64 + 8.0;
        for k in 0..length {
            means.extend([centre + rng.range(-3.0, 3.0), 8.0 + rng.range(-3.0, 3.0)]);
            // σ ≈ 10 px: every pixel of the tile within reach.
            conics.extend([0.01, rng.range(-0.002, 0.002), 0.01]);
            let stopper = tile == lengths.len() - 1 && k < opaque_front;
            opacities.push(if stopper {
                0.99
            } else {
                rng.range(0.004, 0.012)
            });
            values.extend((0..channels).map(|_| rng.range(-1.0, 1.0)));
        }
        work.push(TileWork {
            batch: 0,
            tile,
            gaussians: (next..next + length as u32).collect(),
        });
        next += length as u32;
    }
    assert_gpu_kernels_match_host_kernels(&KernelCase {
        means,
        conics,
        opacities,
        values,
        work,
        gaussians: next as usize,
        batch: 1,
        grid,
        channels,
        segment_entries: segment,
    });
}

/// The same with as many channels as it takes for the pipelined backward (two buffers of
/// per-entry sums) not to fit the device's workgroup memory: the backward then sums one entry
/// at a time, and agrees too (lists cut into segments, as above).
#[cfg(feature = "wgpu")]
#[test]
fn gpu_kernels_match_host_kernels_one_entry_at_a_time() {
    use splatraj_render::fused::cube::{EntrySums, entry_sums_on};

    let device = BackendKind::Wgpu.device().unwrap();
    let channels = (1..=16)
        .find(|&c| entry_sums_on(&device, c) == Some(EntrySums::OneAtATime))
        .expect("a channel count whose pipelined backward does not fit");
    gpu_kernels_match_host_kernels_with(600, channels, STAGE_ENTRIES);
}

#[cfg(feature = "wgpu")]
use splatraj_render::fused::segments::{STAGE_ENTRIES, WHOLE_LISTS};

/// The same with 50 000 Gaussians a pose: the second pose crowds them all into one column of
/// tiles, lists of ~50 000 entries with pixels replaying tens of thousands of them. The
/// backward's per-entry binary tree over the tile's pixels (ten barriers an entry) gave v_means
/// 22 % off there on lavapipe, and biker's pose gradient 90 % off; the two-level sum that
/// replaced it agrees. The lists are cut as a plan cuts them unless asked otherwise (tens of
/// segments a tile).
#[cfg(feature = "wgpu")]
#[test]
fn gpu_kernels_match_host_kernels_on_crowded_lists() {
    gpu_kernels_match_host_kernels_with(
        50_000,
        2,
        splatraj_render::fused::plan::DEFAULT_SEGMENT_ENTRIES,
    );
}

#[cfg(feature = "wgpu")]
fn gpu_kernels_match_host_kernels_with(n: usize, channels: usize, segment_entries: usize) {
    use splatraj_render::tiles::{TILE_SIZE, TileGrid, TileWork};

    let (width, height, batch) = (45, 37, 2);
    let grid = TileGrid::new(width, height);
    let mut rng = common::Rng(0x9e3779b97f4a7c15);
    let (mut means, mut conics, mut opacities, mut values) = (vec![], vec![], vec![], vec![]);
    let mut work = Vec::new();
    for b in 0..batch {
        let mut boxes = Vec::new();
        for g in 0..n {
            // The second pose leaves the right column of tiles empty (boxes end before x = 32).
            let x_max = if b == 0 { width as f64 + 4.0 } else { 8.0 };
            let (mx, my) = (rng.range(-4.0, x_max), rng.range(-4.0, height as f64 + 4.0));
            let (sx, sy, rho) = (
                rng.range(1.0, 6.0),
                rng.range(1.0, 6.0),
                rng.range(-0.6, 0.6),
            );
            let (a, bb, c) = (sx * sx, rho * sx * sy, sy * sy);
            let det = a * c - bb * bb;
            means.extend([mx, my]);
            conics.extend([c / det, -bb / det, a / det]);
            // Every tenth Gaussian is (nearly) opaque: pixels and tiles stop early.
            opacities.push(if g % 10 == 0 {
                0.999
            } else {
                rng.range(0.02, 0.9)
            });
            values.extend((0..channels).map(|_| rng.range(-1.0, 1.0)));
            boxes.push((mx - 3.0 * sx, mx + 3.0 * sx, my - 3.0 * sy, my + 3.0 * sy));
        }
        for tile in 0..grid.tiles_x * grid.tiles_y {
            let (x0, y0) = (
                ((tile % grid.tiles_x) * TILE_SIZE) as f64,
                ((tile / grid.tiles_x) * TILE_SIZE) as f64,
            );
            let x1 = x0 + TILE_SIZE as f64;
            let y1 = y0 + TILE_SIZE as f64;
            let gaussians: Vec<u32> = (0..n as u32)
                .filter(|&g| {
                    let (l, r, t, btm) = boxes[g as usize];
                    r >= x0 && l <= x1 && btm >= y0 && t <= y1
                })
                .collect();
            if !gaussians.is_empty() {
                work.push(TileWork {
                    batch: b,
                    tile,
                    gaussians,
                });
            }
        }
    }
    assert!(
        work.iter().any(|w| w.gaussians.len() > 256),
        "a list longer than one stage"
    );
    assert!(
        work.len() < batch * grid.tiles_x * grid.tiles_y,
        "an empty tile"
    );
    assert_gpu_kernels_match_host_kernels(&KernelCase {
        means,
        conics,
        opacities,
        values,
        work,
        gaussians: n,
        batch,
        grid,
        channels,
        segment_entries,
    });
}

/// Splats in screen space and the tile lists that composite them, for one kernel comparison.
#[cfg(feature = "wgpu")]
struct KernelCase {
    means: Vec<f64>,
    conics: Vec<f64>,
    opacities: Vec<f64>,
    values: Vec<f64>,
    work: Vec<splatraj_render::tiles::TileWork>,
    /// Gaussians a pose (rows `b·gaussians + g`).
    gaussians: usize,
    batch: usize,
    grid: splatraj_render::tiles::TileGrid,
    channels: usize,
    /// The plan's longest segment on the GPU ([`WHOLE_LISTS`]: none cut).
    segment_entries: usize,
}

/// The GPU compositing kernels against the host kernels on `case`, forward and backward, and
/// the GPU's result the same on a second run.
#[cfg(feature = "wgpu")]
fn assert_gpu_kernels_match_host_kernels(case: &KernelCase) {
    use splatraj_render::fused::{CompositePlan, composite_fused};
    use splatraj_render::rasterize::SplatInputs;

    let (n, batch, grid, channels) = (case.gaussians, case.batch, case.grid, case.channels);
    let (width, height) = (grid.width, grid.height);
    let rows = n * batch;
    let pixels = batch * height * width;
    let w_image: Vec<f64> = (0..pixels * (channels + 1))
        .map(|i| ((i * 7919) % 23) as f64 / 23.0 - 0.4)
        .collect();

    let run = |backend: BackendKind| -> Vec<Vec<f64>> {
        let device = backend.device().unwrap().autodiff();
        let t2 = |v: &[f64], cols: usize| {
            Tensor::<2>::from_data(
                TensorData::new(v.to_vec(), [v.len() / cols, cols]),
                (&device, DType::F32),
            )
            .require_grad()
        };
        let (m, c, v) = (
            t2(&case.means, 2),
            t2(&case.conics, 3),
            t2(&case.values, channels),
        );
        let o = Tensor::<1>::from_data(
            TensorData::new(case.opacities.clone(), [rows]),
            (&device, DType::F32),
        )
        .require_grad();
        let inputs = SplatInputs {
            means_2d: m.clone(),
            conics: c.clone(),
            opacities: o.clone(),
            values: v.clone(),
        };
        let out = composite_fused(
            &inputs,
            CompositePlan::new(
                &case.work,
                &splatraj_render::rows::PoseRows::dense(batch, n),
                grid,
            )
            .with_segment_entries(case.segment_entries),
        );
        let weights = |range: std::ops::Range<usize>| {
            let w: Vec<f64> = w_image
                .chunks(channels + 1)
                .flat_map(|px| px[range.clone()].to_vec())
                .collect();
            w
        };
        let w_values = Tensor::<4>::from_data(
            TensorData::new(weights(0..channels), [batch, height, width, channels]),
            (&device, DType::F32),
        );
        let w_alpha = Tensor::<3>::from_data(
            TensorData::new(weights(channels..channels + 1), [batch, height, width]),
            (&device, DType::F32),
        );
        let loss = (out.images.clone() * w_values).sum() + (out.alpha().unwrap() * w_alpha).sum();
        let grads = loss.backward();
        vec![
            host(out.images.clone()),
            host(out.alpha().unwrap()),
            host(m.grad(&grads).unwrap()),
            host(c.grad(&grads).unwrap()),
            host(o.grad(&grads).unwrap()),
            host(v.grad(&grads).unwrap()),
        ]
    };
    let want = run(BackendKind::Flex);
    let got = run(BackendKind::Wgpu);
    let names = [
        "images",
        "alpha",
        "v_means",
        "v_conics",
        "v_opacities",
        "v_values",
    ];
    for ((name, got), want) in names.iter().zip(&got).zip(&want) {
        common::assert_within(
            &format!("{name}, GPU against host kernels"),
            got,
            want,
            1e-3,
        );
    }
    assert_eq!(
        run(BackendKind::Wgpu),
        got,
        "the GPU kernels are deterministic"
    );
}

/// A replay longer than lavapipe's loop budget: llvmpipe ends all loops of an invocation once
/// they have made 65 535 iterations together, and the backward's per-entry sum was a runtime
/// loop of two iterations besides the entry loop's one, so a pixel replaying more than ~21 800
/// entries silently lost the rest: the entries nearest the camera, replayed last. Biker's full
/// frame has tiles of ~23 000 (its pose gradient was 1.1e-3 of its norm off). One tile here: a
/// half-opaque splat in front, 30 000 splats below the 1/255 skip behind it (in the list, never
/// drawn, so the transmittance never stops the replay), a half-opaque one at the back.
#[cfg(feature = "wgpu")]
#[test]
fn gpu_kernels_match_host_kernels_on_a_long_replay() {
    use splatraj_render::tiles::{TileGrid, TileWork};

    let (faint, channels) = (30_000, 1);
    let n = faint + 2;
    let grid = TileGrid::new(16, 16);
    let (mut means, mut conics, mut opacities, mut values) = (vec![], vec![], vec![], vec![]);
    for g in 0..n {
        means.extend([7.5 + (g % 5) as f64 * 0.3, 7.5 - (g % 3) as f64 * 0.4]);
        // σ ≈ 10 px: every pixel of the tile within 1.2σ.
        conics.extend([0.01, 0.001, 0.012]);
        let edge = g == 0 || g == n - 1;
        opacities.push(if edge { 0.5 } else { 0.003 });
        values.push(if edge {
            1.0 - 2.0 * (g % 2) as f64
        } else {
            0.7
        });
    }
    assert_gpu_kernels_match_host_kernels(&KernelCase {
        means,
        conics,
        opacities,
        values,
        work: vec![TileWork {
            batch: 0,
            tile: 0,
            gaussians: (0..n as u32).collect(),
        }],
        gaussians: n,
        batch: 1,
        grid,
        channels,
        // Whole: one pixel's replay of the whole list is what meets lavapipe's loop budget.
        segment_entries: WHOLE_LISTS,
    });
}

/// 3000 Gaussians, a tenth spread far (behind the cameras, beyond the Jacobian's clamp): a
/// dozen of the GPU kernels' cubes a pose, a partial last one.
#[cfg(feature = "wgpu")]
fn gpu_scene(seed: u64) -> Scene {
    let spread = |i: usize| if i.is_multiple_of(10) { 8.0 } else { 1.5 };
    common::random_scene(
        &mut common::Rng(seed),
        3000,
        spread,
        (0.01, 0.2),
        (0.05, 1.0),
    )
}

/// Three poses on both of Rodrigues' branches (ω = 0 among them).
#[cfg(feature = "wgpu")]
fn gpu_poses() -> [Pose; 3] {
    let up = DVec3::new(0.0, -1.0, 0.0);
    [
        Pose::look_at(DVec3::new(3.0, -1.0, 4.0), DVec3::ZERO, up).unwrap(),
        Pose([0.03, -0.04, 0.02, 0.1, 0.2, -4.0]),
        Pose([0.0, 0.0, 0.0, -0.2, 0.1, -5.0]),
    ]
}

/// The GPU's packed rows within f32 rounding of the host's where `in_view` (rows a pass can
/// composite), and its pose gradient within 1e-3 of the host's norm, which it returns.
#[cfg(feature = "wgpu")]
fn assert_gpu_matches_host(
    (rows_gpu, grad_gpu): (&[f64], &[f64]),
    (rows_host, grad_host): (&[f64], &[f64]),
    in_view: &[bool],
) -> f64 {
    use splatraj_render::fused::projection::SPLAT_COLUMNS;

    for (i, (g, h)) in rows_gpu.iter().zip(rows_host).enumerate() {
        assert!(
            !in_view[i / SPLAT_COLUMNS] || (g - h).abs() <= 1e-4 * (1.0 + h.abs()),
            "row value {i} (row {}, column {}): GPU {g} vs host {h}",
            i / SPLAT_COLUMNS,
            i % SPLAT_COLUMNS
        );
    }
    let norm = grad_host.iter().map(|g| g * g).sum::<f64>().sqrt();
    assert!(norm > 1.0, "a gradient to compare");
    for (k, (g, h)) in grad_gpu.iter().zip(grad_host).enumerate() {
        assert!(
            (g - h).abs() <= 1e-3 * norm,
            "dΦ[{}][{}]: GPU {g} vs host {h} (norm {norm})",
            k / 6,
            k % 6
        );
    }
    norm
}

/// The GPU projection kernels against the host kernels, both f32 (the host kernels are checked
/// against the tensor projection in f64, `tests/fused_projection.rs`): 3000 Gaussians (a dozen
/// cubes per pose, a partial last one), a subset out of order with a repeat, three poses on
/// both of Rodrigues' branches (ω = 0 among them), rows behind the camera and beyond the
/// Jacobian's clamp; the packed rows and the pose gradient of a weighted sum of them, with the
/// rows laid out dense and per pose (uneven, one pose without rows).
#[cfg(feature = "wgpu")]
#[test]
fn gpu_projection_matches_host_projection() {
    use splatraj_render::fused::projection::{
        ProjectionCamera, ProjectionPlan, SPLAT_COLUMNS, project_packed,
    };
    use splatraj_render::project::{NEAR_PLANE, SceneTensors};

    let scene = gpu_scene(0x2545f4914f6cdd1d);
    let mut used: Vec<u32> = (0..3000).rev().collect();
    used.push(17);
    let poses = gpu_poses();
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    let intrinsics = Intrinsics::from_fov_x(60.0, 160, 120).unwrap();
    // Rows a pass can composite: in front of the camera and near the image. The others
    // (behind the near plane, thousands of pixels off screen) hold finite values whose f32
    // rounding differs between any two implementations, and no pass sends them a gradient.
    let seen = |row: &[f64]| -> bool {
        row[6] > 0.1 && (row[0] - 80.0).abs() < 320.0 && (row[1] - 60.0).abs() < 240.0
    };
    let camera = ProjectionCamera::new(&intrinsics, NEAR_PLANE);
    // Every pose every Gaussian; and each pose its own rows (pose 1 none, pose 2 more cubes
    // than pose 0), as a pass of several windows lays them out.
    let per_pose = ProjectionPlan::new(
        [&used[..700], &used[1000..2900]].concat(),
        splatraj_render::rows::PoseRows::from_counts([700, 0, 1900]),
        camera,
    );
    for plan in [ProjectionPlan::dense(&used, 3, camera), per_pose] {
        let count = plan.rows.total();
        let mut weights: Vec<f64> = (0..count * SPLAT_COLUMNS)
            .map(|i| ((i * 7919) % 29) as f64 / 29.0 - 0.45)
            .collect();
        let run = |backend: BackendKind, weights: &[f64]| -> (Vec<f64>, Vec<f64>) {
            let device = backend.device().unwrap().autodiff();
            let geometry = SceneTensors::new(&scene, None, &device, DType::F32);
            let pose_tensor = Tensor::<2>::from_data(
                TensorData::new(flat.clone(), [3, 6]),
                (&device, DType::F32),
            )
            .require_grad();
            let rows = project_packed(&geometry, pose_tensor.clone(), plan.clone()); // [R, 7]
            let w = Tensor::<2>::from_data(
                TensorData::new(weights.to_vec(), [count, SPLAT_COLUMNS]),
                (&device, DType::F32),
            );
            let grads = (rows.clone() * w).sum().backward();
            (host(rows), host(pose_tensor.grad(&grads).unwrap()))
        };
        let (rows_host, _) = run(BackendKind::Flex, &weights);
        let in_view: Vec<bool> = rows_host.chunks_exact(SPLAT_COLUMNS).map(seen).collect();
        assert!(
            in_view.iter().filter(|&&s| s).count() > count / 3,
            "most rows are in view"
        );
        for (w, &keep) in weights.chunks_exact_mut(SPLAT_COLUMNS).zip(&in_view) {
            if !keep {
                w.fill(0.0);
            }
        }
        let (_, grad_host) = run(BackendKind::Flex, &weights);
        let (rows_gpu, grad_gpu) = run(BackendKind::Wgpu, &weights);
        assert_gpu_matches_host((&rows_gpu, &grad_gpu), (&rows_host, &grad_host), &in_view);
        assert_eq!(
            run(BackendKind::Wgpu, &weights),
            (rows_gpu, grad_gpu),
            "the GPU kernels are deterministic"
        );
    }
}

#[cfg(feature = "wgpu")]
#[test]
fn gpu_zoomed_projection_matches_host_projection() {
    // The zoom's kernels (fx·s, fy·s, the clamp of s·x/z, d L/ds summed per cube then per
    // pose) on the GPU against the host kernels, f32, zooms in and out.
    use splatraj_render::fused::projection::{
        ProjectionCamera, ProjectionPlan, SPLAT_COLUMNS, project_packed_zoomed,
    };
    use splatraj_render::project::{NEAR_PLANE, SceneTensors};

    let scene = gpu_scene(0x9e3779b97f4a7c15);
    let used: Vec<u32> = (0..3000).collect();
    let poses = gpu_poses();
    let zoom = [1.8f64, 0.6, 2.5];
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    let intrinsics = Intrinsics::from_fov_x(60.0, 160, 120).unwrap();
    // Rows a pass can composite (in front, near the image); see the unzoomed test above.
    let seen = |row: &[f64]| -> bool {
        row[6] > 0.1 && (row[0] - 80.0).abs() < 320.0 && (row[1] - 60.0).abs() < 240.0
    };
    let mut weights: Vec<f64> = (0..poses.len() * used.len() * SPLAT_COLUMNS)
        .map(|i| ((i * 7919) % 29) as f64 / 29.0 - 0.45)
        .collect();
    let run = |backend: BackendKind, weights: &[f64]| -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let device = backend.device().unwrap().autodiff();
        let geometry = SceneTensors::new(&scene, None, &device, DType::F32);
        let pose_tensor =
            Tensor::<2>::from_data(TensorData::new(flat.clone(), [3, 6]), (&device, DType::F32))
                .require_grad();
        let zoom_tensor =
            Tensor::<1>::from_data(TensorData::new(zoom.to_vec(), [3]), (&device, DType::F32))
                .require_grad();
        let camera = ProjectionCamera::new(&intrinsics, NEAR_PLANE);
        let rows = project_packed_zoomed(
            &geometry,
            pose_tensor.clone(),
            Some(zoom_tensor.clone()),
            ProjectionPlan::dense(&used, 3, camera),
        )
        .reshape([3, used.len(), SPLAT_COLUMNS]);
        let w = Tensor::<3>::from_data(
            TensorData::new(weights.to_vec(), [3, used.len(), SPLAT_COLUMNS]),
            (&device, DType::F32),
        );
        let grads = (rows.clone() * w).sum().backward();
        (
            host(rows),
            host(pose_tensor.grad(&grads).unwrap()),
            host(zoom_tensor.grad(&grads).unwrap()),
        )
    };
    let (rows_host, _, _) = run(BackendKind::Flex, &weights);
    let in_view: Vec<bool> = rows_host.chunks_exact(SPLAT_COLUMNS).map(seen).collect();
    assert!(
        in_view.iter().filter(|&&s| s).count() > used.len(),
        "most rows are in view"
    );
    for (w, &keep) in weights.chunks_exact_mut(SPLAT_COLUMNS).zip(&in_view) {
        if !keep {
            w.fill(0.0);
        }
    }
    let (_, grad_host, zoom_host) = run(BackendKind::Flex, &weights);
    let (rows_gpu, grad_gpu, zoom_gpu) = run(BackendKind::Wgpu, &weights);
    let norm = assert_gpu_matches_host((&rows_gpu, &grad_gpu), (&rows_host, &grad_host), &in_view);
    let zoom_norm = zoom_host.iter().map(|g| g * g).sum::<f64>().sqrt();
    let worst = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
    };
    println!(
        "GPU vs host: dΦ {:.1e} of its norm {norm:.1}, ds {:.1e} of its norm {zoom_norm:.1} (GPU {zoom_gpu:?}, host {zoom_host:?})",
        worst(&grad_gpu, &grad_host) / norm,
        worst(&zoom_gpu, &zoom_host) / zoom_norm
    );
    assert!(zoom_norm > 1.0, "a zoom gradient to compare");
    for (b, (g, h)) in zoom_gpu.iter().zip(&zoom_host).enumerate() {
        assert!(
            (g - h).abs() <= 1e-3 * zoom_norm,
            "d/ds[{b}]: GPU {g} vs host {h} (norm {zoom_norm})"
        );
    }
    assert_eq!(
        run(BackendKind::Wgpu, &weights),
        (rows_gpu, grad_gpu, zoom_gpu),
        "the GPU kernels are deterministic"
    );
}

/// The GPU colour kernels against the host kernels, both f32 (the host kernels are checked
/// against the tensor SH colours in f64, `tests/fused_colours.rs`): SH degrees 0 to 3, the
/// rows dense and per pose (uneven, one pose without rows), the colours and the pose gradient
/// of a weighted sum of them.
#[cfg(feature = "wgpu")]
#[test]
fn gpu_colours_match_host_colours() {
    use splatraj_render::fused::colours::colours_of_rows;
    use splatraj_render::fused::projection::{ProjectionCamera, ProjectionPlan};
    use splatraj_render::project::{NEAR_PLANE, SceneTensors};
    use splatraj_render::sh::ShTensors;

    let poses: Vec<f64> = gpu_poses().iter().flat_map(|p| p.0).collect();
    let camera =
        ProjectionCamera::new(&Intrinsics::from_fov_x(60.0, 160, 120).unwrap(), NEAR_PLANE);
    let used: Vec<u32> = (0..3000).rev().collect();
    let per_pose = ProjectionPlan::new(
        [&used[..700], &used[1000..2900]].concat(),
        splatraj_render::rows::PoseRows::from_counts([700, 0, 1900]),
        camera,
    );
    for degree in 0..=3u8 {
        let mut scene = gpu_scene(0x51ed + u64::from(degree));
        let mut rng = common::Rng(u64::from(degree) + 1);
        scene.sh_degree = degree;
        scene.sh = (0..3000 * scene.sh_coeffs() * 3)
            .map(|_| rng.range(-3.0, 3.0) as f32)
            .collect();
        for plan in [ProjectionPlan::dense(&used, 3, camera), per_pose.clone()] {
            let count = plan.rows.total();
            let weights: Vec<f64> = (0..count * 3)
                .map(|i| ((i * 7919) % 29) as f64 / 29.0 - 0.45)
                .collect();
            let run = |backend: BackendKind| -> (Vec<f64>, Vec<f64>) {
                let device = backend.device().unwrap().autodiff();
                let geometry = SceneTensors::new(&scene, None, &device, DType::F32);
                let sh = ShTensors::new(&scene, None, &device, DType::F32);
                let pose_tensor = Tensor::<2>::from_data(
                    TensorData::new(poses.clone(), [3, 6]),
                    (&device, DType::F32),
                )
                .require_grad();
                let rgb = colours_of_rows(&geometry, &sh, pose_tensor.clone(), plan.clone());
                let w = Tensor::<2>::from_data(
                    TensorData::new(weights.clone(), [count, 3]),
                    (&device, DType::F32),
                );
                let grads = (rgb.clone() * w).sum().backward();
                (host(rgb), host(pose_tensor.grad(&grads).unwrap()))
            };
            let (rgb_host, grad_host) = run(BackendKind::Flex);
            let (rgb_gpu, grad_gpu) = run(BackendKind::Wgpu);
            for (i, (g, h)) in rgb_gpu.iter().zip(&rgb_host).enumerate() {
                assert!(
                    (g - h).abs() <= 1e-5 * (1.0 + h.abs()),
                    "degree {degree}, rgb {i}: GPU {g} vs host {h}"
                );
            }
            let norm = grad_host.iter().map(|g| g * g).sum::<f64>().sqrt();
            assert!(
                degree == 0 || norm > 1.0,
                "degree {degree}: a gradient to compare"
            );
            for (k, (g, h)) in grad_gpu.iter().zip(&grad_host).enumerate() {
                assert!(
                    (g - h).abs() <= 1e-4 * norm.max(1.0),
                    "degree {degree}, dΦ[{}][{}]: GPU {g} vs host {h} (norm {norm})",
                    k / 6,
                    k % 6
                );
            }
            assert_eq!(
                run(BackendKind::Wgpu),
                (rgb_gpu, grad_gpu),
                "the GPU kernels are deterministic"
            );
        }
    }
}

/// A GPU's largest buffer bounds a pass: `poses_per_pass` keeps the images within it, and a
/// pass of one pose whose image is larger (possible only on a small device, such as lavapipe's
/// 128 MiB) is refused before any work, naming the buffer, not a panic or a device failure.
#[cfg(feature = "wgpu")]
#[test]
fn a_pass_larger_than_the_gpus_largest_buffer_is_an_error() {
    use splatraj_render::pass_size::{max_buffer_bytes, poses_per_pass};

    let device = BackendKind::Wgpu.device().unwrap();
    let max = max_buffer_bytes(&device).expect("a wgpu device reports its largest buffer");
    let per_pass = poses_per_pass(&device, DType::F32, 1280, 720, 1);
    // Mask and alpha, 4 bytes each.
    assert!(
        (per_pass * 1280 * 720 * 2 * 4) as u64 <= max,
        "{per_pass} poses, max {max}"
    );
    if max > 1 << 30 {
        return; // a large GPU: an image beyond its buffers is too large to test here
    }
    let (scene, mask, _, pose) = setup();
    // Square, its mask and alpha just above the largest buffer.
    let side = ((max / 8) as f64).sqrt() as usize + 16;
    let intrinsics = Intrinsics::from_fov_x(60.0, side, side).unwrap();
    let uploaded = DeviceScene::new(&scene, &device, DType::F32);
    let poses = Tensor::<2>::from_data(
        TensorData::new(pose.0.to_vec(), [1, 6]),
        (&device, DType::F32),
    );
    let request = RenderRequest::new(intrinsics, vec![Channel::Mask(mask)]);
    let message = render(&uploaded, poses, &request)
        .map(|_| ())
        .expect_err("an image beyond the largest buffer is refused")
        .to_string();
    assert!(
        message.contains("a pass's images (1 poses") && message.contains("largest buffer"),
        "{message}"
    );
}

/// The packed rows of a pass (poses × Gaussians used × 7) are one buffer too: 50 poses of a
/// scene of 100 000 Gaussians, all in view, need 140 MB of them, over lavapipe's 128 MiB, and
/// are refused by name (before: a device failure at the next read, as a chain of lost buffers).
#[cfg(feature = "wgpu")]
#[test]
fn a_pass_whose_rows_exceed_the_gpus_largest_buffer_is_an_error() {
    use splatraj_render::pass_size::max_buffer_bytes;

    let device = BackendKind::Wgpu.device().unwrap();
    let (n, batch) = (100_000usize, 50usize);
    if max_buffer_bytes(&device).expect("a wgpu device reports its largest buffer")
        >= (batch * n * 7 * 4) as u64
    {
        return; // a large GPU holds these rows
    }
    let mut scene = Scene::default();
    for i in 0..n {
        let (x, y) = (
            (i % 400) as f32 / 400.0 - 0.5,
            (i / 400) as f32 / 250.0 - 0.5,
        );
        scene.means.push([x, y, 3.0]);
        scene.scales.push([0.01, 0.01, 0.01]);
        scene.rotations.push([1.0, 0.0, 0.0, 0.0]);
        scene.opacities.push(0.5);
        scene.sh.extend([0.5, 0.5, 0.5]);
    }
    let (_, _, intrinsics, pose) = setup();
    let uploaded = DeviceScene::new(&scene, &device, DType::F32);
    let poses = Tensor::<2>::from_data(
        TensorData::new(pose.0.repeat(batch), [batch, 6]),
        (&device, DType::F32),
    );
    let message = refused_depth_pass(&uploaded, poses, intrinsics);
    assert!(
        // Every pose sees every Gaussian: 50 × 100 000 rows.
        message.contains("a pass's packed rows (5000000 pose–Gaussian rows")
            && message.contains("largest buffer"),
        "{message}"
    );
}

/// The error of a depth pass of `poses` that must be refused before any work.
fn refused_depth_pass(scene: &DeviceScene, poses: Tensor<2>, intrinsics: Intrinsics) -> String {
    let request = RenderRequest::new(intrinsics, vec![Channel::Depth]);
    render(scene, poses, &request)
        .map(|_| ())
        .expect_err("the pass is refused")
        .to_string()
}

/// The projection's and colours' kernels put a pass's poses on one axis of their launch grid,
/// which holds 65 535 cubes: a split into passes (`poses_per_pass`, which the metrics and the
/// frames use) keeps under it where the image bound alone would not (16×16 masks: 65 536
/// poses in 128 MiB), and a larger render call is refused before any work instead of failing
/// on the device. The host backends keep the image bound alone.
#[test]
fn a_pass_never_holds_more_poses_than_a_launch_grid_axis() {
    use splatraj_render::backend::Execution;
    use splatraj_render::pass_size::{PASS_IMAGE_BYTES, max_buffer_bytes, poses_per_pass};

    for backend in BackendKind::compiled() {
        let device = backend.device().unwrap();
        // A 16×16 mask and its alpha in f32: 2 KiB a pose.
        let limit = max_buffer_bytes(&device).map_or(PASS_IMAGE_BYTES, |m| m.min(PASS_IMAGE_BYTES));
        let fit = usize::try_from(limit / (16 * 16 * 2 * 4)).unwrap();
        let per_pass = poses_per_pass(&device, DType::F32, 16, 16, 1);
        match Execution::of(&device) {
            Execution::Host => assert_eq!(per_pass, fit, "{backend}"),
            Execution::Kernels => {
                assert_eq!(per_pass, fit.min(65_535), "{backend}");
                let (scene, _, intrinsics, _) = setup();
                let uploaded = DeviceScene::new(&scene, &device, DType::F32);
                let batch = 65_536;
                let poses = Tensor::<2>::zeros([batch, 6], (&device, DType::F32));
                let message = refused_depth_pass(&uploaded, poses, intrinsics);
                assert!(
                    message.contains("a render pass of 65536 poses")
                        && message.contains("at most 65535"),
                    "{message}"
                );
            }
        }
    }
}

/// A GPU kernel stages every channel of 256 entries in workgroup memory, so a device holds only
/// so many channels a composite (lavapipe 16; a feature render of a mask file has one per
/// label). Past that, a pass failed on the device ("Too much shared memory requested"); now
/// its channels are composited in groups that fit and joined: 2·16 + 3 feature channels (three
/// groups, the last partial) give wgpu the image, alpha and pose gradient of flex.
#[cfg(feature = "wgpu")]
#[test]
fn many_channels_are_composited_in_groups_that_fit_the_device() {
    use splatraj_render::fused::cube::channels_per_composite;

    let group = channels_per_composite(&BackendKind::Wgpu.device().unwrap())
        .expect("a wgpu device has a channel limit");
    let dim = 2 * group + 3;
    let (scene, _, intrinsics, pose) = setup();
    let values: Vec<f32> = (0..scene.len() * dim)
        .map(|i| ((i * 7919) % 101) as f32 / 101.0 - 0.3)
        .collect();
    let run = |backend: BackendKind| -> Vec<Vec<f64>> {
        let device = backend.device().unwrap().autodiff();
        let uploaded = DeviceScene::new(&scene, &device, DType::F32);
        let poses = Tensor::<2>::from_data(
            TensorData::new(pose.0.to_vec(), [1, 6]),
            (&device, DType::F32),
        )
        .require_grad();
        let request = RenderRequest::new(
            intrinsics,
            vec![Channel::Features {
                dim,
                values: values.clone(),
            }],
        );
        let out = render(&uploaded, poses.clone(), &request).expect("the pass renders");
        let [_, h, w, c] = out.images.dims();
        let weights: Vec<f32> = (0..h * w * c)
            .map(|i| ((i * 31) % 17) as f32 / 17.0 - 0.5)
            .collect();
        let weights = Tensor::<4>::from_data(
            TensorData::new(weights, [1, h, w, c]),
            (&device, DType::F32),
        );
        let loss = (out.images.clone() * weights).sum() + out.alpha().unwrap().sum();
        let gradient = poses.grad(&loss.backward()).unwrap();
        vec![
            host(out.images.clone()),
            host(out.alpha().unwrap()),
            host(gradient),
        ]
    };
    let (got, want) = (run(BackendKind::Wgpu), run(BackendKind::Flex));
    for ((name, got), want) in ["images", "alpha", "pose gradient"]
        .iter()
        .zip(&got)
        .zip(&want)
    {
        common::assert_within(&format!("{name}, wgpu against flex"), got, want, 1e-4);
    }
}
