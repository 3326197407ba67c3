//! What a mask pass launches, reads and uploads on the GPU backend (lavapipe in CI), counted by
//! `splatraj_render::counters`: the kernel launches of a forward + backward pass do not grow
//! with the number of poses, a pass whose poses the caller holds reads nothing back before its
//! gradient, and the scene is not uploaded again; the same with a zoom per pose whose values
//! the caller holds; and a pass of several objects (an optimisation step's windows, each
//! object alone) launches what one object's pass does; a long tile list is cut into segments
//! for a tracked pass only; burn's fusion merges a chain of elementwise ops; and an RGB pass's
//! colours are one launch whatever the SH degree; a frame's 8-bit levels are packed by one.
//!
//! Its own test binary with one test: the counters are process-wide and the harness runs the
//! tests of one binary side by side.
#![cfg(feature = "wgpu")]

mod common;

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::DVec3;
use splatraj_render::backend::BackendKind;
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::counters::{self, Counts};
use splatraj_render::focus::Surroundings;
use splatraj_render::render::{
    AlphaChannel, Channel, DeviceScene, ObjectMasks, ObjectView, Pruning, RenderRequest, Zoom,
    render_at,
};
use splatraj_scene::Scene;

/// Random Gaussians in a slab 2.5–3.5 in front of a camera at the origin looking down +z.
struct Slab {
    gaussians: usize,
    seed: u64,
    /// Half the slab's extent in x and in y.
    half_width: [f64; 2],
    /// Range of each axis's scale.
    scales: (f64, f64),
    /// Range of the opacities.
    opacities: (f64, f64),
}

impl Slab {
    fn scene(&self) -> Scene {
        let mut rng = common::Rng(self.seed);
        let mut scene = Scene::default();
        let [wx, wy] = self.half_width;
        for _ in 0..self.gaussians {
            scene.means.push([
                rng.range(-wx, wx) as f32,
                rng.range(-wy, wy) as f32,
                rng.range(2.5, 3.5) as f32,
            ]);
            let (lo, hi) = self.scales;
            scene
                .scales
                .push(std::array::from_fn(|_| rng.range(lo, hi) as f32));
            scene
                .rotations
                .push(std::array::from_fn(|_| rng.range(-1.0, 1.0) as f32));
            scene
                .opacities
                .push(rng.range(self.opacities.0, self.opacities.1) as f32);
            scene.sh.extend([0.1, 0.2, 0.3]);
        }
        scene
    }
}

/// 400 Gaussians in a slab in front of the cameras; the first half is the object.
fn scene() -> (Scene, Vec<f32>) {
    let slab = Slab {
        gaussians: 400,
        seed: 0x5eed,
        half_width: [1.0, 0.8],
        scales: (0.03, 0.1),
        opacities: (0.2, 0.9),
    };
    let mask = (0..400).map(|i| if i < 200 { 1.0 } else { 0.0 }).collect();
    (slab.scene(), mask)
}

/// `n` small faint Gaussians spread over the view, all in the object: at 16×16 pixels one
/// tile holds them all.
fn crowded_scene(n: usize) -> (Scene, Vec<f32>) {
    let slab = Slab {
        gaussians: n,
        seed: 0xc0ffee,
        half_width: [0.8, 0.8],
        scales: (0.03, 0.06),
        opacities: (0.02, 0.1),
    };
    (slab.scene(), vec![1.0; n])
}

/// Counts of one forward + backward mask pass (pruned to the object) at `poses`, the pose
/// values given from the host (and with `zoomed`, a zoom per pose, also given from the host);
/// and the counts of its forward alone.
fn pass(
    scene: &DeviceScene,
    mask: &[f32],
    poses: &[Pose],
    device: &Device,
    zoomed: bool,
) -> (Counts, Counts) {
    pass_of(scene, Channel::Mask(mask.to_vec()), poses, device, zoomed)
}

/// [`pass`] of any one mask channel.
fn pass_of(
    scene: &DeviceScene,
    channel: Channel,
    poses: &[Pose],
    device: &Device,
    zoomed: bool,
) -> (Counts, Counts) {
    let intrinsics = Intrinsics::from_fov_x(60.0, 64, 48).unwrap();
    let mut request = RenderRequest::new(intrinsics, vec![channel]);
    request.pruning = Pruning::ObjectOnly;
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    let before = counters::snapshot();
    let tensor = Tensor::<2>::from_data(
        TensorData::new(flat, [poses.len(), 6]),
        (device, DType::F32),
    )
    .require_grad();
    let zoom: Vec<f64> = (0..poses.len()).map(|b| 1.2 + 0.1 * b as f64).collect();
    let zoom_tensor = Tensor::<1>::from_data(
        TensorData::new(zoom.clone(), [poses.len()]),
        (device, DType::F32),
    )
    .require_grad();
    if zoomed {
        request.zoom = Some(Zoom::at(zoom_tensor.clone(), zoom));
    }
    let out = render_at(scene, tensor.clone(), Some(poses), &request).unwrap();
    let loss = out.images.clone().sum() + out.alpha().unwrap().mean();
    let forward = counters::snapshot().since(&before);
    let grads = loss.backward();
    let gradient = tensor.grad(&grads).expect("the poses have a gradient");
    let v: Vec<f64> = splatraj_render::host::to_host(gradient).unwrap();
    assert!(v.iter().any(|g| *g != 0.0), "a gradient");
    let counts = counters::snapshot().since(&before);
    if zoomed {
        let v_zoom = splatraj_render::host::to_host(zoom_tensor.grad(&grads).unwrap()).unwrap();
        assert!(
            v_zoom.iter().all(|g| *g != 0.0),
            "a zoom gradient: {v_zoom:?}"
        );
    }
    (counts, forward)
}

#[test]
fn launches_do_not_grow_with_the_batch_and_reads_stay_at_one() {
    let device = BackendKind::Wgpu.device().unwrap().autodiff();
    let (scene, mask) = scene();
    let uploaded = counters::snapshot();
    let on_device = DeviceScene::new(&scene, &device, DType::F32);
    assert_eq!(counters::snapshot().since(&uploaded).scene_uploads, 1);
    let up = DVec3::new(0.0, -1.0, 0.0);
    let poses: Vec<Pose> = (0..5)
        .map(|i| {
            let x = 0.1 * i as f64 - 0.2;
            Pose::look_at(DVec3::new(x, -0.1, 0.0), DVec3::new(0.0, 0.0, 3.0), up).unwrap()
        })
        .collect();
    // Once each first: kernels compile and may be tuned on their first use at a shape.
    let one = &poses[..1];
    for zoomed in [false, true] {
        pass(&on_device, &mask, one, &device, zoomed);
        pass(&on_device, &mask, &poses, &device, zoomed);
    }
    let (single, single_forward) = pass(&on_device, &mask, one, &device, false);
    let (batch, batch_forward) = pass(&on_device, &mask, &poses, &device, false);
    eprintln!("one pose: {single:?}\nfive poses: {batch:?}");
    assert!(
        single.launches > 0,
        "the GPU backend's launches are counted"
    );
    assert_eq!(
        batch.launches, single.launches,
        "5 poses launch what 1 does: {batch:?} against {single:?}"
    );
    // The forward reads nothing (its poses came from the host); the only read is the gradient.
    assert_eq!(single_forward.reads, 0, "{single_forward:?}");
    assert_eq!(batch_forward.reads, 0, "{batch_forward:?}");
    assert_eq!(batch.reads, 1, "{batch:?}");
    assert_eq!(batch.scene_uploads, 0, "the scene stays on the device");
    // What goes up grows with the pass (lists, indices, mask values), not with the scene.
    assert!(batch.bytes_up > single.bytes_up);

    // A zoom whose values come from the host: still nothing read before the gradient, and
    // launches that do not grow with the batch.
    let (zoomed_single, zoomed_single_forward) = pass(&on_device, &mask, one, &device, true);
    let (zoomed_batch, zoomed_batch_forward) = pass(&on_device, &mask, &poses, &device, true);
    eprintln!("zoomed, one pose: {zoomed_single:?}\nzoomed, five poses: {zoomed_batch:?}");
    assert_eq!(zoomed_single_forward.reads, 0, "{zoomed_single_forward:?}");
    assert_eq!(zoomed_batch_forward.reads, 0, "{zoomed_batch_forward:?}");
    assert_eq!(zoomed_batch.reads, 1, "{zoomed_batch:?}");
    assert_eq!(
        zoomed_batch.launches, zoomed_single.launches,
        "5 zoomed poses launch what 1 does"
    );

    // An optimisation step's one pass: two objects' poses and each object alone launch what
    // one object's pass launches, but for the select that gives each pose its object's mask.
    let halves: Vec<Vec<f32>> = [0..100, 100..200]
        .map(|part| {
            (0..400)
                .map(|i| f32::from(u8::from(part.contains(&i))))
                .collect()
        })
        .into();
    let views: Vec<ObjectView> = [
        (0, Surroundings::Scene),
        (1, Surroundings::Scene),
        (0, Surroundings::Nothing),
        (1, Surroundings::Nothing),
    ]
    .iter()
    .flat_map(|&(object, surroundings)| {
        std::iter::repeat_n(
            ObjectView {
                object,
                surroundings,
            },
            poses.len(),
        )
    })
    .collect();
    let step_poses: Vec<Pose> = (0..4).flat_map(|_| poses.iter().copied()).collect();
    let objects = Channel::ObjectMasks(ObjectMasks {
        masks: halves.into(),
        views,
    });
    pass_of(&on_device, objects.clone(), &step_poses, &device, false);
    let (step, step_forward) = pass_of(&on_device, objects, &step_poses, &device, false);
    eprintln!("a step of two objects and each alone, 20 poses: {step:?}");
    assert!(
        step.launches <= batch.launches + 2,
        "one pass for every window: {step:?} against one window's {batch:?}"
    );
    assert_eq!(step_forward.reads, 0, "{step_forward:?}");
    assert_eq!(step.reads, 1, "{step:?}");
    assert_eq!(step.renders, 1, "{step:?}");

    // Long lists are cut into segments only where a backward follows (fused/segments.rs):
    // burn's autodiff must hand a tracked pass's forward `ForwardUse::ForBackward` through the
    // fusion backend to the CubeCL kernels, and an untracked pass `ImageOnly`.
    let (crowd, crowd_mask) = crowded_scene(1300);
    let crowd = DeviceScene::new(&crowd, &device, DType::F32);
    let one_tile = Intrinsics::from_fov_x(60.0, 16, 16).unwrap();
    let request = RenderRequest::new(one_tile, vec![Channel::Mask(crowd_mask)]);
    let centre = Pose::look_at(DVec3::ZERO, DVec3::new(0.0, 0.0, 3.0), up).unwrap();
    let segments_of = |tracked: bool| {
        let poses = Tensor::<2>::from_data(
            TensorData::new(centre.0.to_vec(), [1, 6]),
            (&device, DType::F32),
        );
        let poses = if tracked { poses.require_grad() } else { poses };
        let before = counters::snapshot();
        let out = render_at(&crowd, poses.clone(), Some(&[centre]), &request).unwrap();
        if tracked {
            let grads = out.images.sum().backward();
            splatraj_render::host::to_host(poses.grad(&grads).unwrap()).unwrap();
        } else {
            splatraj_render::host::to_host(out.images.sum()).unwrap();
        }
        let counts = counters::snapshot().since(&before);
        assert_eq!(counts.renders, 1);
        assert!(
            counts.pairs > 1024,
            "one tile holds every Gaussian: {counts:?}"
        );
        counts.segments
    };
    assert_eq!(
        segments_of(false),
        1,
        "a forward alone composites the list whole"
    );
    assert_eq!(
        segments_of(true),
        2,
        "a tracked pass's 1 300-entry list is cut into segments of 1 024"
    );

    // burn's fusion is on (docs/gpu.md, "Kernel fusion"): a chain of eight elementwise ops, the
    // kind the costs and Adam are made of, runs as fewer kernels than ops (one each without it).
    let x = Tensor::<1>::from_data(TensorData::new(vec![0.5f32; 4096], [4096]), &device);
    let chain = |x: Tensor<1>| {
        ((x.clone() * 2.0 + 1.0).exp() * x.clone() - 3.0)
            .abs()
            .sqrt()
            .mul_scalar(0.5)
            .add(x)
    };
    splatraj_render::host::to_host(chain(x.clone())).unwrap();
    let before = counters::snapshot();
    splatraj_render::host::to_host(chain(x)).unwrap();
    let fused = counters::snapshot().since(&before);
    eprintln!("eight elementwise ops: {fused:?}");
    assert!(
        fused.launches > 0 && fused.launches < 8,
        "eight elementwise ops are fused into fewer kernels: {fused:?}"
    );

    // An RGB pass's colours are one launch whatever the SH degree (`fused/colours`): as burn
    // ops they were about 19 more, and more with the degree. The colours read the row table
    // the projection uploaded: an RGB pass uploads what a mask pass of the same pose does, less
    // the mask's value a row (uploading the table again would be 4 bytes a row and a pose more).
    let rgb_and_mask = |degree: u8| {
        let (mut scene, mask) = self::scene();
        scene.sh_degree = degree;
        let mut rng = common::Rng(5);
        scene.sh = (0..scene.len() * scene.sh_coeffs() * 3)
            .map(|_| rng.range(-0.5, 0.5) as f32)
            .collect();
        let scene = DeviceScene::new(&scene, &device, DType::F32);
        let request_of = |channel: Channel| {
            let mut request =
                RenderRequest::new(Intrinsics::from_fov_x(60.0, 64, 48).unwrap(), vec![channel]);
            request.alpha = AlphaChannel::Dropped;
            request
        };
        let pose = &poses[..1];
        let tensor = Tensor::<2>::from_data(
            TensorData::new(pose[0].0.to_vec(), [1, 6]),
            (&device, DType::F32),
        );
        let count = |request: &RenderRequest| {
            let before = counters::snapshot();
            let out = render_at(&scene, tensor.clone(), Some(pose), request).unwrap();
            splatraj_render::host::to_host(out.images).unwrap();
            counters::snapshot().since(&before)
        };
        let rgb = request_of(Channel::Rgb);
        count(&rgb); // kernels compile on their first use
        (count(&rgb), count(&request_of(Channel::Mask(mask))))
    };
    let ((flat, mask_pass), (view_dependent, _)) = (rgb_and_mask(0), rgb_and_mask(3));
    eprintln!("an RGB pass, SH degree 0: {flat:?}\ndegree 3: {view_dependent:?}");
    eprintln!("a mask pass: {mask_pass:?}");
    assert!(flat.rows > 0 && flat.rows == mask_pass.rows, "{flat:?}");
    assert_eq!(flat.uploads + 1, mask_pass.uploads, "{flat:?}");
    assert_eq!(
        flat.bytes_up + 4 * flat.rows,
        mask_pass.bytes_up,
        "{flat:?}"
    );
    assert_eq!(view_dependent.launches, flat.launches, "{view_dependent:?}");
    assert!(
        view_dependent.launches <= 5,
        "projection, colours, compositing and a fill: {view_dependent:?}"
    );

    // A frame's 8-bit levels are packed by one kernel (`fused/levels`), nothing uploaded: as
    // burn ops they were four launches (the clamp chain, the cast, the places, the sum).
    let [batch, height, width, channels] = [2, 48, 64, 4];
    let mut rng = common::Rng(9);
    let values: Vec<f32> = (0..batch * height * width * channels)
        .map(|_| rng.range(-0.1, 1.1) as f32)
        .collect();
    let images = Tensor::<4>::from_data(
        TensorData::new(values, [batch, height, width, channels]),
        (&device, DType::F32),
    );
    splatraj_render::host::to_host(images.clone()).unwrap();
    let before = counters::snapshot();
    let packed = splatraj_render::images::packed_rgb8(images).into_data();
    let packing = counters::snapshot().since(&before);
    eprintln!("packing a frame's levels: {packing:?}");
    assert_eq!(packed.num_elements(), batch * height * width);
    assert_eq!((packing.launches, packing.uploads), (1, 0), "{packing:?}");
}
