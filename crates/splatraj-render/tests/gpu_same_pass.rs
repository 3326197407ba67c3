//! A GPU pass gives the images, pose gradient and packed levels of the host kernels (flex), and
//! the same again on buffers that held other values and on two-dimensional launch grids. Both
//! stay hidden on small inputs and show on real captures on a real GPU:
//! - the kernels' outputs are allocated without a fill (no launch), so a kernel must write every
//!   element. Fresh memory reads as zeros and may hide one that does not; memory a pool hands
//!   out again holds what this pass's freed buffers or an earlier pass left there. Flex is the
//!   yardstick for the first, and the pass runs again after the free memory is filled with NaN
//!   for the second.
//! - real captures need 2D grids (a step whose 40 poses keep 420 k Gaussians each has more than
//!   65 535 × 256 rows to gather) and no lavapipe-sized input reaches them, so the test lowers the per-axis cap
//!   (`fused::launch_grid::set_axis_cap`) until a small pass does.
//!
//! Its own test binary with one test: the cap and the memory pools are the whole process's.
#![cfg(feature = "wgpu")]

mod common;

use burn::tensor::{DType, Tensor, TensorData};
use glam::DVec3;
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::fused::launch_grid::{MAX_PER_AXIS, set_axis_cap};
use splatraj_render::images::{packed_rgb8, unpack_rgb8};
use splatraj_render::render::{Channel, DeviceScene, RenderRequest, render};
use splatraj_scene::Scene;

/// Gaussians in a 3 m cube at the origin, all in view of [`poses`]: 1 500 rows a pose, so six
/// chunks of 256 for the projection and 18 cubes for the gather over three poses.
const GAUSSIANS: usize = 1_500;

/// Below every count the pass launches (pixels / 256 = 36, work tiles ≥ 36, gather 18,
/// projection chunks 6 a pose) and dividing none of them, so every grid is 2D with spare cubes
/// in its last row, and the projection's cubes each take a second chunk.
const LOW_CAP: usize = 5;

/// Bytes of the large NaN buffer: more than the pass's largest buffer
/// (its slots, 1 500 rows × about 12 tiles × 10 floats × 3 poses ≈ 2 MB) and below lavapipe's
/// largest buffer (128 MiB).
const POISON_PAGE: usize = 64 << 20;

fn scene() -> Scene {
    let mut rng = common::Rng(0x9a1d);
    let mut scene = common::random_scene(&mut rng, GAUSSIANS, |_| 1.5, (0.03, 0.2), (0.05, 0.6));
    // Degree 1: the colours depend on the view, so the fused colours' kernels run too.
    scene.sh = (0..12 * GAUSSIANS)
        .map(|_| rng.range(-0.6, 0.6) as f32)
        .collect();
    scene.sh_degree = 1;
    scene
}

fn poses() -> Vec<Pose> {
    let up = DVec3::new(0.0, -1.0, 0.0);
    [
        DVec3::new(0.3, -0.3, -4.0),
        DVec3::new(-3.5, -0.5, 1.0),
        DVec3::new(2.0, 1.0, 3.0),
    ]
    .map(|eye| Pose::look_at(eye, DVec3::ZERO, up).unwrap())
    .to_vec()
}

/// What one pass gives: its images `[B, H, W, 4]`, the pose gradient of a weighted sum of them
/// and the images' packed levels.
struct Pass {
    images: Vec<f64>,
    gradient: Vec<f64>,
    levels: Vec<i32>,
}

/// Fills free device memory with NaN, so that the next pass's buffers hold NaN where a kernel
/// leaves them unwritten, as far as the pools hand this memory out again (not all of it: a pass
/// also reuses its own freed buffers). CubeCL's default pools (`MemoryConfiguration::Adaptive`)
/// carve larger buffers from pages sized after the largest buffer served and keep those up to
/// 64 KiB in a pool of their own: one buffer larger than any of the pass's, and two of every
/// multiple of 256 bytes up to 64 KiB.
fn poison_free_memory() {
    let device = BackendKind::Wgpu.device().unwrap();
    // burn's fusion frees a dropped tensor's buffer when it next runs its queue: a read runs
    // it, so the last pass's buffers are free for the poison, and the poison's for the next pass.
    let settle = || common::host(Tensor::<1>::zeros([1], (&device, DType::F32)));
    settle();
    let large = std::iter::once(POISON_PAGE / 4);
    let small = (1..=256).flat_map(|k| [64 * k; 2]);
    let held: Vec<Tensor<1>> = large
        .chain(small)
        .map(|n| {
            Tensor::from_data(
                TensorData::new(vec![f32::NAN; n], [n]),
                (&device, DType::F32),
            )
        })
        .collect();
    // A read syncs: every upload has landed before the buffers go back to the pools.
    let first = common::host(held[0].clone().narrow(0, 0, 1));
    assert!(first[0].is_nan(), "the poison is on the device");
    drop(held);
    settle();
}

/// An RGB and mask pass with its pose gradient on `backend` (f32), under the cap in force.
fn pass(backend: BackendKind) -> Pass {
    let device = backend.device().unwrap().autodiff();
    let scene = scene();
    let mask: Vec<f32> = (0..GAUSSIANS).map(|i| f32::from(i % 4 == 0)).collect();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    let poses = poses();
    let request = RenderRequest::new(
        Intrinsics::from_fov_x(70.0, 64, 48).unwrap(),
        vec![Channel::Rgb, Channel::Mask(mask)],
    );
    let tensor = common::pose_tensor(&poses, &device, DType::F32).require_grad();
    let out = render(&on_device, tensor.clone(), &request).unwrap();
    let dims = out.images.dims();
    // Weights of both signs, so the gradient does not hinge on one large sum.
    let mut rng = common::Rng(7);
    let weights: Vec<f32> = (0..dims.iter().product::<usize>())
        .map(|_| rng.range(-1.0, 1.0) as f32)
        .collect();
    let weights = Tensor::<4>::from_data(TensorData::new(weights, dims), (&device, DType::F32));
    let grads = (out.images.clone() * weights).sum().backward();
    let gradient = common::host(tensor.grad(&grads).expect("the poses have a gradient"));
    let levels = packed_rgb8(out.images.clone())
        .into_data()
        .convert::<i32>()
        .try_into_vec::<i32>()
        .unwrap();
    Pass {
        images: common::host(out.images),
        gradient,
        levels,
    }
}

/// Equal values, or how many differ and the first of them (the whole list would be pages).
fn assert_same<T: PartialEq + std::fmt::Debug>(name: &str, got: &[T], want: &[T]) {
    assert_eq!(got.len(), want.len(), "{name}: lengths");
    let apart: Vec<usize> = (0..got.len()).filter(|&i| got[i] != want[i]).collect();
    if let Some(&first) = apart.first() {
        panic!(
            "{name}: {} of {} values differ, the first at {first}: {:?} against {:?}",
            apart.len(),
            got.len(),
            got[first],
            want[first]
        );
    }
}

#[test]
fn a_pass_is_the_same_on_reused_buffers_and_folded_grids() {
    set_axis_cap(MAX_PER_AXIS);
    let host = pass(BackendKind::Flex);
    let first = pass(BackendKind::Wgpu);
    let covered = first.images.iter().filter(|v| **v > 0.05).count();
    assert!(
        covered > first.images.len() / 2,
        "the scene covers the frames: {covered} of {} values",
        first.images.len()
    );
    assert!(
        first.gradient.iter().all(|g| g.is_finite()),
        "a finite gradient"
    );

    // The host kernels are the yardstick: a value the GPU kernels leave unwritten (memory a
    // pool handed out again within the pass) is caught here even where the poison is not read.
    let images_gap = first
        .images
        .iter()
        .zip(&host.images)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
    // f32 on both sides, with the suite's bound (`compiled_backends_agree_on_image_and_gradient`).
    assert!(images_gap < 1e-4, "images {images_gap} from flex's");
    common::assert_within(
        "gradient against flex's",
        &first.gradient,
        &host.gradient,
        1e-4,
    );
    // f32 on either side: a level may land one above or below within ~1e-5 of a half.
    let (gpu, cpu) = (unpack_rgb8(&first.levels), unpack_rgb8(&host.levels));
    let apart = gpu.iter().zip(&cpu).filter(|(a, b)| a != b).count();
    assert!(
        apart <= 8 && gpu.iter().zip(&cpu).all(|(a, b)| a.abs_diff(*b) <= 1),
        "levels: {apart} channel values apart from flex's"
    );

    poison_free_memory();
    let reused = pass(BackendKind::Wgpu);
    // The same kernels on the same grids: every sum in the same order.
    assert_same("images on reused buffers", &reused.images, &first.images);
    assert_same("levels on reused buffers", &reused.levels, &first.levels);
    assert_same(
        "gradient on reused buffers",
        &reused.gradient,
        &first.gradient,
    );

    set_axis_cap(LOW_CAP);
    poison_free_memory();
    let folded = pass(BackendKind::Wgpu);
    set_axis_cap(MAX_PER_AXIS);
    // Per pixel and per row the kernels do the same sums in the same order whatever the grid.
    assert_same("images on folded grids", &folded.images, &first.images);
    assert_same("levels on folded grids", &folded.levels, &first.levels);
    // The pose gradient's partial sums are per cube, and the cubes take other chunks.
    common::assert_within(
        "pose gradient on folded grids",
        &folded.gradient,
        &first.gradient,
        1e-5,
    );
}
