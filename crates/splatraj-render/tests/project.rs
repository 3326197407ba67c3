//! Tensor projection (Gaussians → screen space, batched over poses) against an independent
//! brute-force f64 host computation written here from docs/conventions.md's rules: rotations
//! through glam's quaternions (no Rodrigues), Σ_world as Σ_k s_k² r_k r_kᵀ (no R S Sᵀ Rᵀ product),
//! the 2D covariance from an explicit Jacobian, and the conic from glam's 2×2 inverse.

use std::f64::consts::PI;
use std::time::Instant;

use burn::tensor::{DType, Device, Tensor, TensorData};
use glam::{DMat2, DMat3, DQuat, DVec3};
use splatraj_render::camera::{Intrinsics, Pose};
use splatraj_render::project::{
    NEAR_PLANE, Projected, SceneTensors, project, radii_and_visibility,
};
use splatraj_scene::Scene;

// ---------------------------------------------------------------------------------------------
// Test data

/// SplitMix64: a tiny deterministic generator (the crate has no rand dev-dependency).
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [lo, hi).
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn vec3(&mut self, lo: f64, hi: f64) -> [f32; 3] {
        std::array::from_fn(|_| self.uniform(lo, hi) as f32)
    }
}

fn intrinsics() -> Intrinsics {
    Intrinsics::from_fov_x(60.0, 320, 240).unwrap()
}

/// 50 anisotropic, randomly rotated Gaussians: 40 near the origin (on screen), 10 spread wide
/// so that some are off-screen beyond the Jacobian clamp and some behind the cameras.
fn random_scene(seed: u64) -> Scene {
    let mut rng = Rng(seed);
    let mut scene = Scene::default();
    for i in 0..50 {
        let mean = if i < 40 {
            rng.vec3(-1.5, 1.5)
        } else {
            rng.vec3(-9.0, 9.0)
        };
        scene.means.push(mean);
        scene.scales.push(rng.vec3(0.02, 0.15));
        // Unnormalised on purpose: the code must normalise (w, x, y, z).
        let q: [f32; 4] = std::array::from_fn(|_| rng.uniform(-1.0, 1.0) as f32);
        scene.rotations.push(q);
        scene.opacities.push(rng.uniform(0.1, 1.0) as f32);
    }
    scene
}

/// Three look-at poses around the origin (generic rotations, one with a non-trivial roll).
fn poses() -> Vec<Pose> {
    let up = DVec3::new(0.0, -1.0, 0.0);
    vec![
        Pose::look_at(DVec3::new(4.0, -1.0, 5.0), DVec3::ZERO, up).unwrap(),
        Pose::look_at(DVec3::new(-5.5, -2.0, -1.0), DVec3::new(0.3, 0.2, 0.0), up).unwrap(),
        Pose::look_at(
            DVec3::new(0.5, -6.0, 1.0),
            DVec3::new(0.0, 0.0, 0.2),
            DVec3::new(0.3, 0.0, 1.0),
        )
        .unwrap(),
    ]
}

fn ad_device() -> Device {
    Device::flex().autodiff()
}

fn pose_tensor(poses: &[Pose], device: &Device, dtype: DType) -> Tensor<2> {
    let flat: Vec<f64> = poses.iter().flat_map(|p| p.0).collect();
    Tensor::from_data(TensorData::new(flat, [poses.len(), 6]), (device, dtype))
}

fn values<const D: usize>(t: &Tensor<D>) -> Vec<f64> {
    t.to_data().try_to_vec_as::<f64>().unwrap()
}

// ---------------------------------------------------------------------------------------------
// Independent f64 reference

/// One Gaussian as seen from one pose.
#[derive(Debug, Clone, Copy)]
struct RefSplat {
    uv: [f64; 2],
    z: f64,
    conic: [f64; 3],
    cov: [f64; 3],
    /// Whether x/z or y/z exceeded the Jacobian clamp.
    clamped: bool,
}

/// Σ_world = Σ_k s_k² r_k r_kᵀ with r_k = q·e_k, q the normalised quaternion.
fn ref_world_covariance(scene: &Scene, i: usize) -> DMat3 {
    let [w, x, y, z] = scene.rotations[i].map(f64::from);
    let q = DQuat::from_xyzw(x, y, z, w).normalize();
    let s = scene.scales[i].map(f64::from);
    let mut sigma = DMat3::ZERO;
    for (k, axis) in [DVec3::X, DVec3::Y, DVec3::Z].into_iter().enumerate() {
        let r = q * axis;
        let outer = DMat3::from_cols(r * r.x, r * r.y, r * r.z);
        sigma += outer * (s[k] * s[k]);
    }
    sigma
}

/// Rules of docs/conventions.md "Rendering", evaluated directly (no cull: the caller masks).
fn ref_project(scene: &Scene, pose: [f64; 6], k: &Intrinsics) -> Vec<RefSplat> {
    let omega = DVec3::new(pose[0], pose[1], pose[2]);
    let centre = DVec3::new(pose[3], pose[4], pose[5]);
    let r_wc = DMat3::from_quat(DQuat::from_scaled_axis(omega));
    let w = r_wc.transpose();
    let lim_x = 1.3 * (0.5 * k.width as f64 / k.fx);
    let lim_y = 1.3 * (0.5 * k.height as f64 / k.fy);
    (0..scene.len())
        .map(|i| {
            let p = w * (DVec3::from(scene.means[i].map(f64::from)) - centre);
            let z = p.z;
            let sigma_cam = w * ref_world_covariance(scene, i) * w.transpose();
            let (xz, yz) = (p.x / z, p.y / z);
            let (cx, cy) = (xz.clamp(-lim_x, lim_x), yz.clamp(-lim_y, lim_y));
            let j = [
                DVec3::new(k.fx / z, 0.0, -k.fx * cx / z),
                DVec3::new(0.0, k.fy / z, -k.fy * cy / z),
            ];
            let e = |a: usize, b: usize| j[a].dot(sigma_cam * j[b]);
            let cov = DMat2::from_cols_array(&[e(0, 0) + 0.3, e(1, 0), e(0, 1), e(1, 1) + 0.3]);
            let inv = cov.inverse();
            RefSplat {
                uv: [k.fx * xz + k.cx, k.fy * yz + k.cy],
                z,
                conic: [inv.x_axis.x, inv.y_axis.x, inv.y_axis.y],
                cov: [cov.x_axis.x, cov.y_axis.x, cov.y_axis.y],
                clamped: xz.abs() > lim_x || yz.abs() > lim_y,
            }
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Comparisons

/// Largest error of `got` against the reference over entries the reference sees in front of
/// the near plane, each error relative to a per-quantity scale (see the body).
struct Errors {
    means: f64,
    depth: f64,
    conics: f64,
    cov: f64,
    compared: usize,
    clamped: usize,
}

fn compare(got: &Projected, scene: &Scene, poses: &[Pose], k: &Intrinsics) -> Errors {
    let n = scene.len();
    let (uv, z, conic, cov) = (
        values(&got.means_2d),
        values(&got.depth),
        values(&got.conics),
        values(&got.cov_2d),
    );
    assert_eq!(uv.len(), poses.len() * n * 2);
    assert_eq!(conic.len(), poses.len() * n * 3);
    let mut e = Errors {
        means: 0.0,
        depth: 0.0,
        conics: 0.0,
        cov: 0.0,
        compared: 0,
        clamped: 0,
    };
    for (b, pose) in poses.iter().enumerate() {
        for (i, r) in ref_project(scene, pose.0, k).into_iter().enumerate() {
            let at = b * n + i;
            // Depth is meaningful for every entry (the cull reads it).
            e.depth = e.depth.max((z[at] - r.z).abs() / r.z.abs().max(1.0));
            if r.z <= NEAR_PLANE {
                continue;
            }
            e.compared += 1;
            e.clamped += usize::from(r.clamped);
            // Pixel coordinates relative to the image size (or their own size off-screen).
            let uv_scale = r.uv[0].abs().max(r.uv[1].abs()).max(k.width as f64);
            for d in 0..2 {
                e.means = e.means.max((uv[2 * at + d] - r.uv[d]).abs() / uv_scale);
            }
            // A symmetric 2×2's entries are bounded by its largest diagonal entry.
            let conic_scale = r.conic[0].abs().max(r.conic[2].abs());
            let cov_scale = r.cov[0].abs().max(r.cov[2].abs());
            for d in 0..3 {
                e.conics = e
                    .conics
                    .max((conic[3 * at + d] - r.conic[d]).abs() / conic_scale);
                e.cov = e.cov.max((cov[3 * at + d] - r.cov[d]).abs() / cov_scale);
            }
        }
    }
    e
}

// ---------------------------------------------------------------------------------------------
// 1. Values against the reference, f64

#[test]
fn f64_projection_matches_brute_force_reference() {
    let scene = random_scene(7);
    let poses = poses();
    let k = intrinsics();
    let device = Device::flex();
    let tensors = SceneTensors::new(&scene, None, &device, DType::F64);
    let got = project(&tensors, pose_tensor(&poses, &device, DType::F64), &k);
    assert_eq!(got.depth.dims(), [3, 50]);
    assert_eq!(got.means_2d.dims(), [3, 50, 2]);
    assert_eq!(got.conics.dims(), [3, 50, 3]);
    let e = compare(&got, &scene, &poses, &k);
    println!(
        "compared {} (clamped {}): means {:.1e} depth {:.1e} conics {:.1e} cov {:.1e}",
        e.compared, e.clamped, e.means, e.depth, e.conics, e.cov
    );
    // The scene must exercise the Jacobian clamp and the near-plane cull.
    assert!(e.clamped >= 5, "only {} clamped entries", e.clamped);
    assert!(e.compared < 150, "no entry behind the near plane");
    for (name, err) in [
        ("means_2d", e.means),
        ("depth", e.depth),
        ("conics", e.conics),
        ("cov_2d", e.cov),
    ] {
        assert!(err <= 1e-9, "{name}: relative error {err:.2e}");
    }
}

#[test]
fn index_subset_and_visibility_match_reference() {
    let scene = random_scene(11);
    let poses = poses();
    let k = intrinsics();
    let device = Device::flex();
    let subset: Vec<usize> = vec![49, 3, 17, 42, 0, 41];
    let tensors = SceneTensors::new(&scene, Some(&subset), &device, DType::F64);
    assert_eq!(tensors.len(), subset.len());
    let got = project(&tensors, pose_tensor(&poses, &device, DType::F64), &k);
    let (radii, visible) = radii_and_visibility(&got, NEAR_PLANE);
    assert_eq!(radii.len(), poses.len() * subset.len());
    let conic = values(&got.conics);
    for (b, pose) in poses.iter().enumerate() {
        let reference = ref_project(&scene, pose.0, &k);
        for (j, &i) in subset.iter().enumerate() {
            let r = reference[i];
            let at = b * subset.len() + j;
            assert_eq!(visible[at], r.z > NEAR_PLANE, "pose {b} Gaussian {i}");
            if !visible[at] {
                assert_eq!(radii[at], 0.0);
                continue;
            }
            assert!((conic[3 * at] - r.conic[0]).abs() <= 1e-9 * r.conic[0]);
            // Radius from the eigenvalues of the reference Σ_2D (via the quadratic formula on
            // the characteristic polynomial, written out independently).
            let [a, bb, c] = r.cov;
            let lambda = 0.5 * (a + c) + (0.25 * (a - c) * (a - c) + bb * bb).sqrt();
            assert_eq!(
                radii[at],
                (3.0 * lambda.sqrt()).ceil() as f32,
                "radius {at}"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// 2. Pose gradients against central finite differences of the reference

struct Weights {
    uv: Vec<f64>,
    conic: Vec<f64>,
    depth: Vec<f64>,
    /// 1 for entries in front of the near plane at the unperturbed poses, else 0.
    mask: Vec<f64>,
}

fn ref_loss(scene: &Scene, poses: &[[f64; 6]], k: &Intrinsics, w: &Weights) -> f64 {
    let n = scene.len();
    let mut loss = 0.0;
    for (b, pose) in poses.iter().enumerate() {
        for (i, r) in ref_project(scene, *pose, k).into_iter().enumerate() {
            let at = b * n + i;
            if w.mask[at] == 0.0 {
                continue;
            }
            loss += w.uv[2 * at] * r.uv[0] + w.uv[2 * at + 1] * r.uv[1];
            loss += (0..3)
                .map(|d| w.conic[3 * at + d] * r.conic[d])
                .sum::<f64>();
            loss += w.depth[at] * r.z;
        }
    }
    loss
}

fn check_gradient(scene: &Scene, poses: &[Pose]) {
    let k = intrinsics();
    let device = ad_device();
    let n = scene.len();
    let bn = poses.len() * n;
    let mut rng = Rng(99);
    let mask: Vec<f64> = poses
        .iter()
        .flat_map(|p| ref_project(scene, p.0, &k))
        .map(|r| f64::from(u8::from(r.z > NEAR_PLANE)))
        .collect();
    let w = Weights {
        uv: (0..2 * bn).map(|_| rng.uniform(-1.0, 1.0)).collect(),
        conic: (0..3 * bn).map(|_| rng.uniform(-1.0, 1.0)).collect(),
        depth: (0..bn).map(|_| rng.uniform(-1.0, 1.0)).collect(),
        mask,
    };
    let b = poses.len();
    let t = |v: &[f64], shape: [usize; 3]| {
        Tensor::<3>::from_data(TensorData::new(v.to_vec(), shape), (&device, DType::F64))
    };
    let mask_t = t(&w.mask, [b, n, 1]);
    let tensors = SceneTensors::new(scene, None, &device, DType::F64);
    let phi = pose_tensor(poses, &device, DType::F64).require_grad();
    let out = project(&tensors, phi.clone(), &k);
    let loss = (out.means_2d * t(&w.uv, [b, n, 2]) * mask_t.clone()).sum()
        + (out.conics * t(&w.conic, [b, n, 3]) * mask_t.clone()).sum()
        + (out.depth.unsqueeze_dim::<3>(2) * t(&w.depth, [b, n, 1]) * mask_t).sum();
    let grads = loss.backward();
    let grad = values(&phi.grad(&grads).unwrap());

    let base: Vec<[f64; 6]> = poses.iter().map(|p| p.0).collect();
    let h = 1e-6;
    let mut worst = 0.0f64;
    for pb in 0..b {
        let fd: Vec<f64> = (0..6)
            .map(|d| {
                let (mut plus, mut minus) = (base.clone(), base.clone());
                plus[pb][d] += h;
                minus[pb][d] -= h;
                (ref_loss(scene, &plus, &k, &w) - ref_loss(scene, &minus, &k, &w)) / (2.0 * h)
            })
            .collect();
        let scale = fd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for d in 0..6 {
            let got = grad[6 * pb + d];
            let err = (got - fd[d]).abs() / scale;
            worst = worst.max(err);
            assert!(
                err <= 1e-5,
                "pose {pb} component {d}: autodiff {got}, finite differences {}, rel {err:.2e}",
                fd[d]
            );
        }
    }
    println!("pose gradient: worst relative error {worst:.1e}");
}

#[test]
fn pose_gradient_matches_finite_differences_at_generic_poses() {
    check_gradient(&random_scene(7), &poses());
}

#[test]
fn pose_gradient_matches_finite_differences_at_zero_rotation() {
    // ω = 0 exactly: the camera looks along +z from behind the scene.
    let poses = [
        Pose([0.0, 0.0, 0.0, 0.3, -0.2, -6.0]),
        Pose([0.0, 0.0, 0.0, -1.0, 0.5, -4.0]),
    ];
    check_gradient(&random_scene(21), &poses);
}

// ---------------------------------------------------------------------------------------------
// 3. Hard cases stay finite

/// Gaussians at and around the camera centre c on both sides of the near plane (for a camera
/// looking along +z or, rotated by ≈π about y, along −z), with extreme scales.
fn hard_scene(c: DVec3) -> Scene {
    let mut scene = Scene::default();
    let mut push = |offset: [f64; 3], scale: [f32; 3], rot: [f32; 4]| {
        let p = c + DVec3::from(offset);
        scene.means.push([p.x as f32, p.y as f32, p.z as f32]);
        scene.scales.push(scale);
        scene.rotations.push(rot);
        scene.opacities.push(0.5);
    };
    let id = [1.0, 0.0, 0.0, 0.0];
    let tilted = [0.9, 0.3, -0.2, 0.1];
    for scale in [
        [0.1f32; 3],
        [1e-8; 3],
        [1e4; 3],
        [1e-8, 1e-8, 1e4],
        [1e4, 1e-8, 1.0],
    ] {
        for rot in [id, tilted] {
            push([0.0, 0.0, 0.0], scale, rot); // at the camera centre exactly
            for side in [1.0, -1.0] {
                push([0.0, 0.0, side * 0.01], scale, rot); // on the near plane
                push([0.0, 0.0, side * 0.005], scale, rot); // just inside it
                push([0.003, -0.002, side * 0.02], scale, rot); // just beyond it
                push([5.0, 1.0, side * 0.02], scale, rot); // far off-screen, near z
                push([0.2, 0.1, side * 3.0], scale, rot); // ordinary
                push([0.0, 0.0, side * 1e3], scale, rot); // far away
            }
        }
    }
    scene
}

fn assert_finite(name: &str, v: &[f64]) {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        panic!("{name}[{i}] = {}", v[i]);
    }
}

#[test]
fn hard_cases_are_finite_in_values_and_gradients() {
    let c = DVec3::new(0.5, -0.25, 2.0);
    let scene = hard_scene(c);
    // The 4K camera's focal length (≈5.6k px) makes Σ_2D ≈ 1e20 px² for the 1e4-scale
    // Gaussians at the near plane: det(Σ_2D) itself would overflow f32.
    for k in [
        intrinsics(),
        Intrinsics::from_fov_x(40.0, 4096, 3072).unwrap(),
    ] {
        hard_cases_for(&scene, c, &k);
    }
}

fn hard_cases_for(scene: &Scene, c: DVec3, k: &Intrinsics) {
    let near_pi = DVec3::new(0.0, 1.0, 0.0) * (PI - 1e-6);
    let tilted_near_pi = DVec3::new(0.3, 0.9, -0.2).normalize() * (PI - 1e-6);
    let poses = [
        Pose([0.0, 0.0, 0.0, c.x, c.y, c.z]),
        Pose([near_pi.x, near_pi.y, near_pi.z, c.x, c.y, c.z]),
        Pose([
            tilted_near_pi.x,
            tilted_near_pi.y,
            tilted_near_pi.z,
            c.x,
            c.y,
            c.z,
        ]),
    ];
    let device = ad_device();
    for dtype in [DType::F32, DType::F64] {
        let tensors = SceneTensors::new(scene, None, &device, dtype);
        let phi = pose_tensor(&poses, &device, dtype).require_grad();
        let out = project(&tensors, phi.clone(), k);
        for (name, v) in [
            ("means_2d", values(&out.means_2d)),
            ("depth", values(&out.depth)),
            ("conics", values(&out.conics)),
            ("cov_2d", values(&out.cov_2d)),
        ] {
            assert_finite(&format!("{dtype:?} {name}"), &v);
        }
        let (radii, visible) = radii_and_visibility(&out, NEAR_PLANE);
        assert!(radii.iter().all(|r| r.is_finite()));
        // Culled entries included: their garbage must be finite for the gradient too. Every
        // output gets its own small weight so that no term cancels another.
        let loss = out.means_2d.sum().mul_scalar(1e-3)
            + out.depth.sum()
            + out.conics.sum()
            + out.cov_2d.sum().mul_scalar(1e-20);
        let grads = loss.backward();
        assert_finite(
            &format!("{dtype:?} pose gradient"),
            &values(&phi.grad(&grads).unwrap()),
        );

        // Cull decisions against the reference depth (the visibility must not depend on
        // precision for these clear-cut cases, apart from the degenerate needles).
        let n = scene.len();
        for (b, pose) in poses.iter().enumerate() {
            for (i, r) in ref_project(scene, pose.0, k).into_iter().enumerate() {
                let at = b * n + i;
                if r.z <= NEAR_PLANE {
                    assert!(!visible[at], "{dtype:?} pose {b} Gaussian {i} z = {}", r.z);
                } else if r.z > 0.015 && scene.scales[i] == [0.1; 3] {
                    assert!(visible[at], "{dtype:?} pose {b} Gaussian {i} z = {}", r.z);
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// 4. f32 agrees with f64

#[test]
fn f32_matches_f64_reference() {
    let scene = random_scene(7);
    let poses = poses();
    let k = intrinsics();
    let device = Device::flex();
    let tensors = SceneTensors::new(&scene, None, &device, DType::F32);
    let got = project(&tensors, pose_tensor(&poses, &device, DType::F32), &k);
    assert_eq!(got.conics.dtype(), DType::F32);
    let e = compare(&got, &scene, &poses, &k);
    println!(
        "f32: means {:.1e} depth {:.1e} conics {:.1e} cov {:.1e}",
        e.means, e.depth, e.conics, e.cov
    );
    for (name, err) in [
        ("means_2d", e.means),
        ("depth", e.depth),
        ("conics", e.conics),
        ("cov_2d", e.cov),
    ] {
        assert!(err <= 1e-4, "{name}: relative error {err:.2e}");
    }
}

// ---------------------------------------------------------------------------------------------
// Timing (not a check): cargo test --release -p splatraj-render --test project -- --ignored --nocapture

#[test]
#[ignore = "timing only; run in release"]
fn timing_100k_gaussians_batch_8() {
    let mut rng = Rng(5);
    let mut scene = Scene::default();
    for _ in 0..100_000 {
        scene.means.push(rng.vec3(-3.0, 3.0));
        scene.scales.push(rng.vec3(0.005, 0.05));
        scene
            .rotations
            .push(std::array::from_fn(|_| rng.uniform(-1.0, 1.0) as f32));
        scene.opacities.push(0.5);
    }
    let k = intrinsics();
    let poses: Vec<Pose> = (0..8)
        .map(|i| {
            let a = i as f64 * 0.7;
            Pose::look_at(
                DVec3::new(8.0 * a.cos(), -1.0, 8.0 * a.sin()),
                DVec3::ZERO,
                DVec3::new(0.0, -1.0, 0.0),
            )
            .unwrap()
        })
        .collect();
    let device = ad_device();
    let tensors = SceneTensors::new(&scene, None, &device, DType::F32);
    let reps = 5;
    for _ in 0..2 {
        let t0 = Instant::now();
        for _ in 0..reps {
            let out = project(&tensors, pose_tensor(&poses, &device, DType::F32), &k);
            let _ = values(&out.conics.sum());
        }
        let fwd = t0.elapsed().as_secs_f64() / reps as f64;
        let t0 = Instant::now();
        for _ in 0..reps {
            let phi = pose_tensor(&poses, &device, DType::F32).require_grad();
            let out = project(&tensors, phi.clone(), &k);
            let loss = out.means_2d.sum() + out.conics.sum() + out.depth.sum();
            let grads = loss.backward();
            let _ = values(&phi.grad(&grads).unwrap());
        }
        let both = t0.elapsed().as_secs_f64() / reps as f64;
        println!(
            "100k × 8 f32 flex: forward {:.1} ms, forward+backward {:.1} ms",
            fwd * 1e3,
            both * 1e3
        );
    }
}
