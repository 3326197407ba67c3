//! A GPU mask pass with its gradient finishes when rayon's global pool has one worker and the
//! pass runs on it, as the `splatraj` binary runs its commands (`RAYON_NUM_THREADS=1`, a
//! one-core machine). It hung there: burn's fusion runs our ops on its device thread while the
//! only worker waits for it, and their host work waited for that worker
//! (`src/fused/host_pool.rs`).
//!
//! Its own test binary with one test: it sets the global pool's size, which a process does once.
#![cfg(feature = "wgpu")]

mod common;

use std::sync::mpsc;
use std::time::Duration;

use burn::tensor::DType;
use splatraj_render::backend::{BackendKind, has_f64};
use splatraj_render::camera::Intrinsics;
use splatraj_render::render::{Channel, DeviceScene, Pruning, RenderRequest, render_at};

/// Far longer than the pass takes on lavapipe on two cores (a few seconds, compiling included).
const HUNG_AFTER: Duration = Duration::from_secs(240);

/// The pose gradient of one pruned mask pass at the shared test poses, on wgpu in `dtype`
/// (f64 composites with the host kernels, called from the device thread too).
fn pose_gradient_on_wgpu(dtype: DType) -> Vec<f64> {
    let device = BackendKind::Wgpu.device().unwrap().autodiff();
    let mut scene = common::projection_scene(7);
    scene.sh = vec![0.5; 3 * scene.len()];
    let mask: Vec<f32> = (0..scene.len()).map(|i| f32::from(i < 30)).collect();
    let on_device = DeviceScene::new(&scene, &device, dtype);
    let poses = common::projection_poses();
    let mut request = RenderRequest::new(
        Intrinsics::from_fov_x(60.0, 64, 48).unwrap(),
        vec![Channel::Mask(mask)],
    );
    request.pruning = Pruning::ObjectOnly;
    let tensor = common::pose_tensor(&poses, &device, dtype).require_grad();
    let out = render_at(&on_device, tensor.clone(), Some(&poses), &request).unwrap();
    let grads = out.images.sum().backward();
    common::host(tensor.grad(&grads).expect("the poses have a gradient"))
}

#[test]
fn a_gpu_pass_on_the_only_worker_of_the_pool_finishes() {
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .expect("the first and only pool this process builds");
    // f64 where the device has it (lavapipe's Vulkan; not wgpu on OpenGL or Metal).
    let device = BackendKind::Wgpu.device().unwrap();
    let dtypes: Vec<DType> = [DType::F32, DType::F64]
        .into_iter()
        .filter(|&dtype| dtype == DType::F32 || has_f64(&device))
        .collect();
    let passes = dtypes.len();
    let (sender, receiver) = mpsc::channel();
    // On a thread of its own, so that a hang fails the test instead of stopping the suite.
    std::thread::spawn(move || {
        for dtype in dtypes {
            let gradient = rayon::scope(|_| pose_gradient_on_wgpu(dtype));
            sender.send((dtype, gradient)).ok();
        }
    });
    for _ in 0..passes {
        let (dtype, gradient) = receiver.recv_timeout(HUNG_AFTER).unwrap_or_else(|_| {
            panic!("a pass on the pool's only worker did not finish in {HUNG_AFTER:?}: hung")
        });
        assert!(
            gradient.iter().all(|g| g.is_finite()) && gradient.iter().any(|g| *g != 0.0),
            "{dtype:?}: a finite, non-zero pose gradient: {gradient:?}"
        );
    }
}
